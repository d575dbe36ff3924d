//! Which catalog: the URL, its default, and its redaction.

use std::fmt;
use std::path::{Path, PathBuf};

use crate::error::CatalogError;

/// The environment variable naming the catalog when no `--catalog` is given.
pub const CATALOG_ENV: &str = "GYROCAL_CATALOG";

/// Where the catalog is: an SQLite file (`sqlite:PATH`, the default) or a PostgreSQL database
/// (`postgres://user@host[:port]/db`).
///
/// A password in a PostgreSQL URL works but is discouraged: put it in `PGPASSWORD` or
/// `~/.pgpass` (libpq's conventions, which the driver follows). Either way it is never shown:
/// [`fmt::Display`] and [`fmt::Debug`] print the URL with the password replaced by `***`, and
/// every error message of this crate is scrubbed of it.
#[derive(Clone, PartialEq, Eq)]
pub enum CatalogUrl {
    /// An SQLite database file (created when missing, with its directory).
    Sqlite(PathBuf),
    /// A PostgreSQL connection URL, as given (with any password).
    Postgres(String),
}

impl CatalogUrl {
    /// Parses `sqlite:PATH` (also `sqlite://PATH`; `sqlite:///abs/path` is `/abs/path`) or
    /// `postgres://...` / `postgresql://...`.
    pub fn parse(text: &str) -> Result<CatalogUrl, CatalogError> {
        let text = text.trim();
        if let Some(rest) = text.strip_prefix("sqlite:") {
            let path = rest.strip_prefix("//").unwrap_or(rest);
            let path = path.split('?').next().unwrap_or(path);
            if path.is_empty() {
                return Err(CatalogError::BadUrl {
                    url: text.to_string(),
                    message: "no file after `sqlite:` (write sqlite:PATH)".into(),
                });
            }
            return Ok(CatalogUrl::Sqlite(PathBuf::from(path)));
        }
        if text.starts_with("postgres://") || text.starts_with("postgresql://") {
            let url = CatalogUrl::Postgres(text.to_string());
            if text.split_once("://").is_some_and(|(_, r)| r.is_empty()) {
                return Err(CatalogError::BadUrl {
                    url: url.redacted(),
                    message: "no host or database after `postgres://`".into(),
                });
            }
            return Ok(url);
        }
        Err(CatalogError::BadUrl {
            url: redact(text),
            message: "a catalog is `sqlite:PATH` or `postgres://user@host/db`".into(),
        })
    }

    /// The default catalog: `$XDG_DATA_HOME/gyrocal/catalog.sqlite`, else
    /// `$HOME/.local/share/gyrocal/catalog.sqlite`.
    pub fn default_sqlite() -> Result<CatalogUrl, CatalogError> {
        let base = std::env::var_os("XDG_DATA_HOME")
            .filter(|v| !v.is_empty() && Path::new(v).is_absolute())
            .map(PathBuf::from)
            .or_else(|| {
                std::env::var_os("HOME")
                    .filter(|v| !v.is_empty())
                    .map(|h| PathBuf::from(h).join(".local/share"))
            });
        match base {
            Some(base) => Ok(CatalogUrl::Sqlite(base.join("gyrocal").join("catalog.sqlite"))),
            None => Err(CatalogError::BadUrl {
                url: String::new(),
                message: "no default catalog: neither XDG_DATA_HOME nor HOME is set; give --catalog sqlite:PATH".into(),
            }),
        }
    }

    /// True for the SQLite backend.
    pub fn is_sqlite(&self) -> bool {
        matches!(self, CatalogUrl::Sqlite(_))
    }

    /// The URL with any password replaced by `***`: what messages show.
    pub fn redacted(&self) -> String {
        match self {
            CatalogUrl::Sqlite(p) => format!("sqlite:{}", p.display()),
            CatalogUrl::Postgres(u) => redact(u),
        }
    }

    /// The password written in the URL, if any (to scrub driver messages).
    pub(crate) fn password(&self) -> Option<String> {
        match self {
            CatalogUrl::Sqlite(_) => None,
            CatalogUrl::Postgres(u) => password_of(u),
        }
    }

    /// `message` with the URL's password (as written and percent-decoded) replaced by `***`.
    pub(crate) fn scrub(&self, message: &str) -> String {
        let mut out = message.to_string();
        if let CatalogUrl::Postgres(u) = self {
            out = out.replace(u.as_str(), &redact(u));
        }
        if let Some(pw) = self.password().filter(|p| !p.is_empty()) {
            out = out.replace(&pw, "***");
            let decoded = percent_decode(&pw);
            if !decoded.is_empty() {
                out = out.replace(&decoded, "***");
            }
        }
        out
    }
}

impl fmt::Display for CatalogUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.redacted())
    }
}

impl fmt::Debug for CatalogUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "CatalogUrl({})", self.redacted())
    }
}

/// The `user:password@` part's bounds in a URL: (start of userinfo, end of userinfo). A text
/// that is not quite a URL (`postgres//lab:pw@db`, `lab:pw@db`: a typo the parser refuses, in
/// a message that quotes it) has its userinfo after the last `/` before the `@`, so that its
/// password is found too: more may be hidden, never less.
fn userinfo(url: &str) -> Option<(usize, usize)> {
    let start = url.find("://").map_or(0, |i| i + 3);
    let rest = &url[start..];
    let end_authority = rest.find(['?', '#']).unwrap_or(rest.len());
    let at = rest[..end_authority].rfind('@')?;
    let from = if start == 0 {
        rest[..at].rfind('/').map_or(0, |i| i + 1)
    } else {
        0
    };
    Some((start + from, start + at))
}

fn password_of(url: &str) -> Option<String> {
    let mut found = None;
    if let Some((s, e)) = userinfo(url)
        && let Some(colon) = url[s..e].find(':')
    {
        found = Some(url[s + colon + 1..e].to_string());
    }
    if found.is_none()
        && let Some((_, query)) = url.split_once('?')
    {
        for pair in query.split('&') {
            if let Some(v) = pair.strip_prefix("password=") {
                found = Some(v.to_string());
            }
        }
    }
    found
}

/// A URL with its password (in the userinfo or a `password=` parameter) replaced by `***`.
pub fn redact(url: &str) -> String {
    let mut out = url.to_string();
    if let Some((s, e)) = userinfo(url)
        && let Some(colon) = url[s..e].find(':')
    {
        out = format!("{}***{}", &url[..s + colon + 1], &url[e..]);
    }
    if let Some((base, query)) = out.clone().split_once('?') {
        let query: Vec<String> = query
            .split('&')
            .map(|pair| {
                if pair.starts_with("password=") {
                    "password=***".to_string()
                } else {
                    pair.to_string()
                }
            })
            .collect();
        out = format!("{base}?{}", query.join("&"));
    }
    out
}

fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%'
            && i + 2 < b.len()
            && let Some(v) = s
                .get(i + 1..i + 3)
                .and_then(|h| u8::from_str_radix(h, 16).ok())
        {
            out.push(v);
            i += 3;
            continue;
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The catalog to use: `flag` (`--catalog`), else the environment's [`CATALOG_ENV`], else
/// `station_catalog` (the station file's `catalog` key), else [`CatalogUrl::default_sqlite`].
/// Empty strings count as absent.
pub fn resolve(
    flag: Option<&str>,
    station_catalog: Option<&str>,
) -> Result<CatalogUrl, CatalogError> {
    let env = std::env::var(CATALOG_ENV).ok();
    let chosen = [flag, env.as_deref(), station_catalog]
        .into_iter()
        .flatten()
        .find(|s| !s.trim().is_empty());
    match chosen {
        Some(text) => CatalogUrl::parse(text),
        None => CatalogUrl::default_sqlite(),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn passwords_never_show() {
        let u =
            CatalogUrl::parse("postgres://lab:s3cr%40t@db.lab:5433/gyro?sslmode=disable").unwrap();
        assert_eq!(
            u.redacted(),
            "postgres://lab:***@db.lab:5433/gyro?sslmode=disable"
        );
        assert!(!format!("{u} {u:?}").contains("s3cr"));
        assert_eq!(
            u.scrub("bad password s3cr@t for s3cr%40t"),
            "bad password *** for ***"
        );
        let q = CatalogUrl::parse("postgres://lab@db/gyro?password=hunter2&x=1").unwrap();
        assert_eq!(q.redacted(), "postgres://lab@db/gyro?password=***&x=1");
        assert_eq!(q.scrub("hunter2"), "***");
        let none = CatalogUrl::parse("postgres://lab@db/gyro").unwrap();
        assert_eq!(none.redacted(), "postgres://lab@db/gyro");
        let bad = CatalogUrl::parse("mysql://u:pw@h/db").unwrap_err();
        assert!(!bad.to_string().contains("pw@"), "{bad}");
        // a typo that is not a URL at all still keeps its password out of the message
        for typo in [
            "postgres//lab:hunter2@db/x",
            "postgres:/lab:hunter2@db/x",
            "lab:hunter2@db/x",
        ] {
            let bad = CatalogUrl::parse(typo).unwrap_err().to_string();
            assert!(!bad.contains("hunter2"), "{bad}");
            assert!(bad.contains("***@db/x"), "{bad}");
        }
    }

    #[test]
    fn sqlite_forms() {
        assert_eq!(
            CatalogUrl::parse("sqlite:/tmp/c.sqlite").unwrap(),
            CatalogUrl::Sqlite("/tmp/c.sqlite".into())
        );
        assert_eq!(
            CatalogUrl::parse("sqlite:///tmp/c.sqlite").unwrap(),
            CatalogUrl::Sqlite("/tmp/c.sqlite".into())
        );
        assert_eq!(
            CatalogUrl::parse("sqlite:rel.db").unwrap(),
            CatalogUrl::Sqlite("rel.db".into())
        );
        assert!(CatalogUrl::parse("sqlite:").is_err());
    }
}
