//! gyrocal-serve: the lab's live view in a browser (`gyrocal serve`), read-only.
//!
//! What it serves, over one or more run-directory roots and, when given, the catalog:
//!
//! - `/`: the dashboard (runs running now with phase, step n/N, ETA, last reading; runs
//!   finished today with their verdicts; stale runs marked);
//! - `/run/ROOT/NAME`: a run's page (its state, the mean voltage against rate with the fitted
//!   line, the step table, its files, and its own `report.html` once written);
//! - `/gyro/SERIAL`: a gyro's history (the catalog's history page);
//! - `/api/runs`, `/api/run/ROOT/NAME`, `/api/gyro/SERIAL`: the same as JSON;
//! - `/api/events`: server-sent events, one `run` event per run whose `live.json` or
//!   `manifest.json` changed (the roots are polled: [`POLL_INTERVAL`], bounded work), and one
//!   per notification of the catalog;
//! - `/live/HOST/RUN_ID` (and `/part/live/...`, `/api/live/...`): a run known through the
//!   catalog's `live_runs` (another bench's), or the run directory of that name under a root.
//!
//! With a PostgreSQL catalog the server also `LISTEN`s on `gyrocal_live` ([`bus`]): the runs
//! every bench publishes there (see `gyrocal_catalog::LiveBus`) are shown beside the roots'
//! runs (a run in both once, from its directory), each notification re-reads that run's row
//! and is pushed to the event streams, and after a lost connection every row is read again.
//!
//! The catalog may come after the server ([`catalog`]): one that does not answer at the
//! start is tried again in the background until it opens; meanwhile the gyro pages answer
//! 503 ("not reachable yet") and the dashboard says so beside the catalog's name.
//!
//! Why polling and files: a run publishes its live state into its own directory
//! ([`gyrocal_run::live`]) and never waits on a viewer; the server only reads. A stopped or
//! slow server costs the run nothing.
//!
//! Security ([`check_bind`], [`App::router`]): loopback by default; another address only with a
//! token, checked on every request as `Authorization: Bearer TOKEN` or the cookie that
//! `/login?token=TOKEN` sets; GET only; no file outside the roots (a name is one path
//! component, never hidden, never `..`, after percent-decoding; symlinks are never followed);
//! every text escaped ([`pages::esc`]); the catalog's URL shown only redacted.
//!
//! Limits ([`limits`]): at most [`MAX_CONNECTIONS`] connections at once (more wait in the
//! kernel's backlog, answered as slots free), at most [`MAX_EVENT_STREAMS`] event streams
//! (more are answered 503, so streams can never take every connection), every request's
//! head read within [`HEADER_TIMEOUT`] (the next one's too, on a kept-alive connection) and a
//! connection with no traffic either way for [`IDLE_TIMEOUT`] closed (a slow or silent client
//! cannot hold a slot; an event stream's keep-alive is traffic), URI, headers and body
//! bounded.

pub mod bus;
pub mod catalog;
pub mod limits;
pub mod pages;
pub mod plots;
pub mod runs;

pub use catalog::{CatalogNow, CatalogSource};
pub use limits::{HEADER_TIMEOUT, IDLE_TIMEOUT, MAX_CONNECTIONS, MAX_HEADER_BYTES};

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, SystemTime};

use axum::Router;
use axum::extract::{Path as UrlPath, Query, Request, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use axum::response::{Html, IntoResponse, Redirect, Response};
use axum::routing::get;
use tokio::net::TcpListener;
use tokio::sync::{Semaphore, broadcast, watch};

use runs::{RunKey, run_dir};

/// How often the roots' `live.json` and `manifest.json` are looked at for changes.
pub const POLL_INTERVAL: Duration = Duration::from_millis(250);
/// The most event streams at once; more are answered 503 (fewer than
/// [`MAX_CONNECTIONS`]: pages and answers always find a connection).
pub const MAX_EVENT_STREAMS: usize = 192;
/// The longest request URI accepted.
pub const MAX_URI: usize = 4096;
/// The largest request body accepted (the server takes none: GET only).
pub const MAX_BODY: usize = 16 * 1024;
/// The shortest token accepted for a non-loopback address.
pub const MIN_TOKEN_LEN: usize = 12;
/// The cookie `/login` sets.
pub const COOKIE: &str = "gyrocal_token";

/// Why the server cannot start.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// A non-loopback address without a (long enough) token.
    #[error(
        "{addr}: serving on an address other than loopback needs a token of at least \
         {MIN_TOKEN_LEN} characters (--token or $GYROCAL_SERVE_TOKEN): without one, anyone on \
         the network could read every run"
    )]
    NoToken {
        /// The address asked for.
        addr: SocketAddr,
    },
    /// The address could not be bound.
    #[error("{addr}: cannot listen: {source}")]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// The cause.
        source: std::io::Error,
    },
    /// The server stopped on an I/O error.
    #[error("the server stopped: {0}")]
    Io(#[from] std::io::Error),
}

/// What kind of failure a [`ServeError`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServeErrorKind {
    /// Bad input: a public address without a token.
    NoToken,
    /// The address could not be bound.
    Bind,
    /// I/O while serving.
    Io,
}

impl ServeError {
    /// What kind of failure this is.
    pub fn kind(&self) -> ServeErrorKind {
        match self {
            ServeError::NoToken { .. } => ServeErrorKind::NoToken,
            ServeError::Bind { .. } => ServeErrorKind::Bind,
            ServeError::Io(_) => ServeErrorKind::Io,
        }
    }
}

/// Refuses a non-loopback `addr` without a token of at least [`MIN_TOKEN_LEN`] characters.
pub fn check_bind(addr: &SocketAddr, token: Option<&str>) -> Result<(), ServeError> {
    if addr.ip().is_loopback() || token.is_some_and(|t| t.len() >= MIN_TOKEN_LEN) {
        Ok(())
    } else {
        Err(ServeError::NoToken { addr: *addr })
    }
}

/// What the server serves.
#[derive(Debug, Clone, Default)]
pub struct ServeConfig {
    /// The run-directory roots (a run is a directory directly under one).
    pub roots: Vec<PathBuf>,
    /// The token every request must carry; `None`: none asked (loopback only).
    pub token: Option<String>,
    /// The catalog, for the gyro pages and (PostgreSQL) the other benches' live runs: open,
    /// or to be opened once it answers ([`catalog`]).
    pub catalog: CatalogSource,
    /// The catalog's URL: pages and answers show it redacted only (never its password).
    pub catalog_url: Option<gyrocal_catalog::CatalogUrl>,
    /// A running run is stale once its live state is this old; `None`: [`runs::STALE_AFTER`].
    pub stale_after: Option<Duration>,
}

struct AppState {
    cfg: ServeConfig,
    /// The catalog now (see [`catalog`]): kept by [`App::follow_catalog`].
    catalog: watch::Sender<CatalogNow>,
    /// The runs known through the catalog's `live_runs` (kept by [`App::follow_catalog`]).
    live: bus::LiveRuns,
    /// The catalog's URL as shown: redacted.
    catalog_shown: Option<String>,
    events: broadcast::Sender<String>,
    streams: Arc<Semaphore>,
}

type Shared = Arc<AppState>;

/// The application: its router and the poller that feeds `/api/events`.
pub struct App {
    state: Shared,
}

impl App {
    /// An application over `cfg`.
    pub fn new(cfg: ServeConfig) -> App {
        let (events, _) = broadcast::channel(1024);
        App {
            state: Arc::new(AppState {
                catalog_shown: cfg.catalog_url.as_ref().map(|u| u.redacted()),
                catalog: watch::Sender::new(CatalogNow::at_start(&cfg.catalog)),
                cfg,
                live: bus::LiveRuns::default(),
                events,
                streams: Arc::new(Semaphore::new(MAX_EVENT_STREAMS)),
            }),
        }
    }

    /// The routes (see the crate docs), with the token check and the limits.
    pub fn router(&self) -> Router {
        router(self.state.clone())
    }

    /// Polls the roots forever, sending one event per changed run (see [`POLL_INTERVAL`]).
    pub async fn poll(&self) {
        let mut seen =
            std::collections::HashMap::<RunKey, (Option<SystemTime>, Option<SystemTime>)>::new();
        let mut interval = tokio::time::interval(POLL_INTERVAL);
        interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            interval.tick().await;
            let roots = self.state.cfg.roots.clone();
            // directory listing and stats are blocking calls: off the runtime's workers
            let found = tokio::task::spawn_blocking(move || stamps(&roots))
                .await
                .unwrap_or_default();
            let mut changed = Vec::new();
            for (key, stamp) in &found {
                if seen.get(key) != Some(stamp) {
                    changed.push(key.clone());
                }
            }
            let first = seen.is_empty();
            seen = found.into_iter().collect();
            if first {
                continue;
            }
            for key in changed {
                let data = serde_json::json!({
                    "root": key.root, "name": key.name, "href": key.href()
                });
                let _ = self.state.events.send(data.to_string());
            }
        }
    }

    /// The catalog now, and its changes: a [`CatalogSource::Later`] one turns from
    /// [`CatalogNow::Waiting`] to [`CatalogNow::Open`] once it answers (for the caller to say).
    pub fn catalog_now(&self) -> watch::Receiver<CatalogNow> {
        self.state.catalog.subscribe()
    }

    /// Opens a [`CatalogSource::Later`] catalog once it answers (see [`catalog`]); then, with
    /// a PostgreSQL catalog, listens to its notifications forever, keeping the runs known
    /// through it and sending one event per change, and prunes its old live rows at the
    /// start and hourly (see [`bus`]). Returns when there is nothing (more) to do: no
    /// catalog, or one that carries no live runs (SQLite).
    pub async fn follow_catalog(&self) {
        let catalog = match &self.state.cfg.catalog {
            CatalogSource::None => return,
            CatalogSource::Open(c) => c.clone(),
            CatalogSource::Later(url) => {
                let c = catalog::open_when_it_answers(url).await;
                self.state.catalog.send_replace(CatalogNow::Open(c.clone()));
                c
            }
        };
        if !catalog.carries_live() {
            return;
        }
        tokio::join!(
            bus::listen(&catalog, &self.state.live, &self.state.events),
            bus::prune(&catalog, &self.state.live),
        );
    }

    /// Serves on `listener` (and polls the roots, and follows the catalog, see
    /// [`App::follow_catalog`]) until the process ends.
    pub async fn serve(self, listener: TcpListener) -> Result<(), ServeError> {
        self.serve_limited(limits::Limited::new(listener)).await
    }

    /// [`App::serve`] on a listener with explicit limits.
    pub async fn serve_limited(self, limited: limits::Limited) -> Result<(), ServeError> {
        let app = self.router();
        tokio::select! {
            () = limits::serve_connections(limited, app) => Ok(()),
            () = self.poll() => Ok(()),
            () = async { self.follow_catalog().await; std::future::pending::<()>().await } => Ok(()),
        }
    }
}

/// The modification times of each run's `live.json` and `manifest.json`.
#[allow(clippy::type_complexity)]
fn stamps(roots: &[PathBuf]) -> Vec<(RunKey, (Option<SystemTime>, Option<SystemTime>))> {
    let mtime = |p: PathBuf| std::fs::symlink_metadata(p).and_then(|m| m.modified()).ok();
    let mut out = Vec::new();
    for (i, root) in roots.iter().enumerate() {
        for (name, dir) in runs::list_dirs(root) {
            let stamp = (
                mtime(dir.join(gyrocal_run::live::LIVE_JSON)),
                mtime(dir.join("manifest.json")),
            );
            out.push((RunKey::local(i, name), stamp));
        }
    }
    out
}

fn router(state: Shared) -> Router {
    Router::new()
        .route("/", get(dashboard))
        .route("/live.js", get(live_js))
        .route("/login", get(login))
        .route("/part/dashboard", get(dashboard_part))
        .route("/run/{root}/{name}", get(run_page))
        .route("/part/run/{root}/{name}", get(run_part))
        .route("/run/{root}/{name}/report.html", get(run_report))
        .route("/run/{root}/{name}/files/{file}", get(run_file))
        .route("/live/{host}/{name}", get(live_page))
        .route("/part/live/{host}/{name}", get(live_part))
        .route("/api/live/{host}/{name}", get(api_live))
        .route("/gyro/{serial}", get(gyro_page))
        .route("/api/runs", get(api_runs))
        .route("/api/run/{root}/{name}", get(api_run))
        .route("/api/gyro/{serial}", get(api_gyro))
        .route("/api/events", get(api_events))
        .fallback(|| async { not_found("no such page") })
        .layer(middleware::from_fn_with_state(state.clone(), guard))
        .layer(tower_http::limit::RequestBodyLimitLayer::new(MAX_BODY))
        .with_state(state)
}

/// Equal in time whatever the position of the first difference.
fn same(a: &str, b: &str) -> bool {
    a.len() == b.len()
        && a.bytes()
            .zip(b.bytes())
            .fold(0u8, |acc, (x, y)| acc | (x ^ y))
            == 0
}

fn token_of(headers: &HeaderMap) -> Option<String> {
    if let Some(v) = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
    {
        return Some(v.trim().to_string());
    }
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .find_map(|c| {
            let (k, v) = c.trim().split_once('=')?;
            (k == COOKIE).then(|| v.to_string())
        })
}

/// The limits, the token check and the security headers, on every request.
async fn guard(State(st): State<Shared>, req: Request, next: Next) -> Response {
    if req.uri().to_string().len() > MAX_URI {
        return (StatusCode::URI_TOO_LONG, "URI too long").into_response();
    }
    let header_bytes: usize = req
        .headers()
        .iter()
        .map(|(k, v)| k.as_str().len() + v.len() + 4)
        .sum();
    if header_bytes > MAX_HEADER_BYTES {
        return (
            StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
            "request headers too large",
        )
            .into_response();
    }
    if let Some(token) = &st.cfg.token
        && req.uri().path() != "/login"
        && !token_of(req.headers()).is_some_and(|t| same(&t, token))
    {
        return (
            StatusCode::UNAUTHORIZED,
            "a token is needed: open /login?token=TOKEN once, or send Authorization: Bearer TOKEN",
        )
            .into_response();
    }
    let mut res = next.run(req).await;
    let h = res.headers_mut();
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(
            "default-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data:; \
             frame-ancestors 'none'",
        ),
    );
    res
}

#[derive(serde::Deserialize)]
struct LoginQuery {
    token: Option<String>,
}

async fn login(State(st): State<Shared>, Query(q): Query<LoginQuery>) -> Response {
    match (&st.cfg.token, q.token) {
        (None, _) => Redirect::to("/").into_response(),
        (Some(t), Some(given)) if same(t, &given) => {
            let cookie = format!("{COOKIE}={given}; Path=/; HttpOnly; SameSite=Strict");
            let mut res = Redirect::to("/").into_response();
            if let Ok(v) = HeaderValue::from_str(&cookie) {
                res.headers_mut().insert(header::SET_COOKIE, v);
            }
            res
        }
        _ => (StatusCode::UNAUTHORIZED, "wrong token").into_response(),
    }
}

fn not_found(what: &str) -> Response {
    (
        StatusCode::NOT_FOUND,
        Html(pages::message("Not found", what)),
    )
        .into_response()
}

async fn live_js() -> Response {
    (
        [(header::CONTENT_TYPE, "text/javascript; charset=utf-8")],
        pages::LIVE_JS,
    )
        .into_response()
}

/// Every run: the roots' (read off the runtime's workers), then the catalog's others.
async fn all_runs(st: &Shared) -> Vec<runs::RunView> {
    let roots = st.cfg.roots.clone();
    let stale = st.cfg.stale_after.unwrap_or(runs::STALE_AFTER);
    let local =
        tokio::task::spawn_blocking(move || runs::all_with(&roots, SystemTime::now(), stale))
            .await
            .unwrap_or_default();
    runs::merge(local, &st.live.rows(), SystemTime::now())
}

fn today() -> String {
    gyrocal_files::rfc3339_utc(SystemTime::now())
        .chars()
        .take(10)
        .collect()
}

/// The catalog as the pages name it: redacted, and said when it does not answer yet.
fn catalog_label(st: &Shared) -> Option<String> {
    let shown = st.catalog_shown.clone()?;
    Some(match *st.catalog.borrow() {
        CatalogNow::Waiting => format!("{shown} (not reachable yet: tried again until it answers)"),
        _ => shown,
    })
}

async fn dashboard_html(st: &Shared) -> String {
    let all = all_runs(st).await;
    pages::dashboard_part(&all, &today(), catalog_label(st).as_deref())
}

async fn dashboard(State(st): State<Shared>) -> Html<String> {
    Html(pages::dashboard(&dashboard_html(&st).await))
}

async fn dashboard_part(State(st): State<Shared>) -> Html<String> {
    Html(dashboard_html(&st).await)
}

/// The run `name` under root `root`, when it is one (see [`runs::run_dir`]).
async fn detail(st: &Shared, root: usize, name: String) -> Option<(runs::RunDetail, PathBuf)> {
    let root_dir = st.cfg.roots.get(root)?.clone();
    let stale = st.cfg.stale_after.unwrap_or(runs::STALE_AFTER);
    tokio::task::spawn_blocking(move || {
        let dir = run_dir(&root_dir, &name)?;
        let d = runs::view_with(RunKey::local(root, name), &dir, SystemTime::now(), stale)?;
        Some((d, dir))
    })
    .await
    .ok()
    .flatten()
}

async fn run_page(
    State(st): State<Shared>,
    UrlPath((root, name)): UrlPath<(usize, String)>,
) -> Response {
    match detail(&st, root, name).await {
        Some((d, dir)) => rendered(move || pages::run_page(&d, Some(&dir))).await,
        None => not_found("no such run"),
    }
}

async fn run_part(
    State(st): State<Shared>,
    UrlPath((root, name)): UrlPath<(usize, String)>,
) -> Response {
    match detail(&st, root, name).await {
        Some((d, dir)) => rendered(move || pages::run_part(&d, Some(&dir))).await,
        None => not_found("no such run"),
    }
}

/// The run `name` of `host`: the run directory of that name under a root when there is one
/// (the truth), else the catalog's row.
async fn live_detail(st: &Shared, host: String, name: String) -> Option<runs::RunDetail> {
    let roots = st.cfg.roots.clone();
    let local_name = name.clone();
    let local = tokio::task::spawn_blocking(move || {
        roots.iter().enumerate().find_map(|(i, root)| {
            let dir = run_dir(root, &local_name)?;
            runs::view(
                RunKey::local(i, local_name.clone()),
                &dir,
                SystemTime::now(),
            )
        })
    })
    .await
    .ok()
    .flatten();
    if local.is_some() {
        return local;
    }
    let row = st.live.get(&host, &name)?;
    Some(runs::from_row(&row, SystemTime::now()))
}

async fn live_page(
    State(st): State<Shared>,
    UrlPath((host, name)): UrlPath<(String, String)>,
) -> Response {
    match live_detail(&st, host, name).await {
        Some(d) => rendered(move || pages::run_page(&d, None)).await,
        None => not_found("no such run"),
    }
}

async fn live_part(
    State(st): State<Shared>,
    UrlPath((host, name)): UrlPath<(String, String)>,
) -> Response {
    match live_detail(&st, host, name).await {
        Some(d) => rendered(move || pages::run_part(&d, None)).await,
        None => not_found("no such run"),
    }
}

async fn api_live(
    State(st): State<Shared>,
    UrlPath((host, name)): UrlPath<(String, String)>,
) -> Response {
    match live_detail(&st, host, name).await {
        Some(d) => axum::Json(d).into_response(),
        None => (
            StatusCode::NOT_FOUND,
            axum::Json(serde_json::json!({"error": "no such run"})),
        )
            .into_response(),
    }
}

/// A page drawn off the runtime's workers (it reads `allan.json`, `temps.csv` and draws plots).
async fn rendered(page: impl FnOnce() -> String + Send + 'static) -> Response {
    match tokio::task::spawn_blocking(page).await {
        Ok(html) => Html(html).into_response(),
        Err(_) => (
            StatusCode::INTERNAL_SERVER_ERROR,
            "the page could not be drawn",
        )
            .into_response(),
    }
}

/// A regular file directly in a run directory (never through a symlink), capped at 256 MiB.
async fn file_in_run(st: &Shared, root: usize, name: String, file: String) -> Option<Vec<u8>> {
    if !runs::safe_name(&file) {
        return None;
    }
    let root_dir = st.cfg.roots.get(root)?.clone();
    tokio::task::spawn_blocking(move || {
        let path = run_dir(&root_dir, &name)?.join(&file);
        let meta = std::fs::symlink_metadata(&path).ok()?;
        (meta.is_file() && meta.len() <= 256 << 20).then_some(())?;
        std::fs::read(&path).ok()
    })
    .await
    .ok()
    .flatten()
}

async fn run_report(
    State(st): State<Shared>,
    UrlPath((root, name)): UrlPath<(usize, String)>,
) -> Response {
    match file_in_run(&st, root, name, "report.html".into()).await {
        Some(b) => ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], b).into_response(),
        None => not_found("this run has no report yet"),
    }
}

async fn run_file(
    State(st): State<Shared>,
    UrlPath((root, name, file)): UrlPath<(usize, String, String)>,
) -> Response {
    // shown as text (or downloaded), never rendered: a run directory's file is not a page
    let kind = if file.ends_with(".csv")
        || file.ends_with(".json")
        || file.ends_with(".log")
        || file.ends_with(".toml")
    {
        "text/plain; charset=utf-8"
    } else {
        "application/octet-stream"
    };
    match file_in_run(&st, root, name, file).await {
        Some(b) => ([(header::CONTENT_TYPE, kind)], b).into_response(),
        None => not_found("no such file"),
    }
}

async fn api_runs(State(st): State<Shared>) -> Response {
    let all = all_runs(&st).await;
    axum::Json(serde_json::json!({
        "runs": all,
        "catalog": st.catalog_shown,
        "now_utc": gyrocal_files::rfc3339_utc(SystemTime::now()),
    }))
    .into_response()
}

async fn api_run(
    State(st): State<Shared>,
    UrlPath((root, name)): UrlPath<(usize, String)>,
) -> Response {
    match detail(&st, root, name).await {
        Some((d, _)) => axum::Json(d).into_response(),
        None => (
            StatusCode::NOT_FOUND,
            axum::Json(serde_json::json!({"error": "no such run"})),
        )
            .into_response(),
    }
}

#[derive(serde::Deserialize)]
struct GyroQuery {
    include_simulated: Option<String>,
}

async fn history(
    st: &Shared,
    serial: &str,
    q: &GyroQuery,
) -> Result<gyrocal_catalog::History, (StatusCode, String)> {
    let now = st.catalog.borrow().clone();
    let catalog = match now {
        CatalogNow::Open(c) => c,
        CatalogNow::Waiting => {
            return Err((
                StatusCode::SERVICE_UNAVAILABLE,
                "the catalog is not reachable yet: the server tries it again until it \
                 answers, and this page works once it does"
                    .into(),
            ));
        }
        CatalogNow::None => {
            return Err((
                StatusCode::NOT_FOUND,
                "no catalog: start gyrocal serve with --catalog for a gyro's history".into(),
            ));
        }
    };
    let sim = q.include_simulated.as_deref().is_some_and(|v| v != "0");
    catalog.history(serial, sim).await.map_err(|e| {
        // the error may name the catalog: said in the server's log, not on the page
        tracing::warn!("history of {serial}: {e}");
        if e.kind() == gyrocal_catalog::ErrorKind::Unreachable {
            (
                StatusCode::SERVICE_UNAVAILABLE,
                "the catalog does not answer now (see the server's log)".into(),
            )
        } else {
            (
                StatusCode::INTERNAL_SERVER_ERROR,
                "the catalog could not be read (see the server's log)".into(),
            )
        }
    })
}

async fn gyro_page(
    State(st): State<Shared>,
    UrlPath(serial): UrlPath<String>,
    Query(q): Query<GyroQuery>,
) -> Response {
    match history(&st, &serial, &q).await {
        Ok(h) => Html(gyrocal_report::history::render(&h)).into_response(),
        Err((code, msg)) => (code, Html(pages::message("No history", &msg))).into_response(),
    }
}

async fn api_gyro(
    State(st): State<Shared>,
    UrlPath(serial): UrlPath<String>,
    Query(q): Query<GyroQuery>,
) -> Response {
    match history(&st, &serial, &q).await {
        Ok(h) => axum::Json(h).into_response(),
        Err((code, msg)) => (code, axum::Json(serde_json::json!({ "error": msg }))).into_response(),
    }
}

async fn api_events(State(st): State<Shared>) -> Response {
    let Ok(slot) = st.streams.clone().try_acquire_owned() else {
        return (StatusCode::SERVICE_UNAVAILABLE, "too many event streams").into_response();
    };
    let rx = st.events.subscribe();
    let stream = futures_util::stream::unfold((rx, slot), |(mut rx, slot)| async move {
        let data = match rx.recv().await {
            Ok(data) => data,
            // a slow reader missed some: tell it to reload everything
            Err(broadcast::error::RecvError::Lagged(_)) => "{\"all\":true}".to_string(),
            Err(broadcast::error::RecvError::Closed) => return None,
        };
        let ev = SseEvent::default().event("run").data(data);
        Some((Ok::<_, std::convert::Infallible>(ev), (rx, slot)))
    });
    Sse::new(stream)
        .keep_alive(KeepAlive::new().interval(Duration::from_secs(15)))
        .into_response()
}

/// Binds `addr` (refused without a token off loopback, see [`check_bind`]).
pub async fn bind(addr: SocketAddr, token: Option<&str>) -> Result<TcpListener, ServeError> {
    check_bind(&addr, token)?;
    TcpListener::bind(addr)
        .await
        .map_err(|source| ServeError::Bind { addr, source })
}
