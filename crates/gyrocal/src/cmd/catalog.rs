//! `gyrocal catalog import DIR...` and `gyrocal catalog rebuild ROOT`: fill the calibration
//! catalog from run directories (the source of truth). Also the catalog opening shared by
//! `gyrocal runs` and `gyrocal history`, which create nothing (a missing SQLite file is an
//! error, not a new empty catalog) and refuse a damaged file rather than list less than it
//! held.
//!
//! A damaged SQLite catalog is repaired by `gyrocal catalog rebuild ROOT`: the damaged file
//! is moved aside (`catalog.sqlite.damaged-<UTC time>`, kept) and a new one is filled from
//! the run directories, which hold every run.

use std::path::PathBuf;

use clap::{Args, Subcommand};
use gyrocal_catalog::{Catalog, CatalogError, CatalogUrl, ErrorKind};

use crate::BadInput;

/// The `--catalog` option of the catalog commands.
#[derive(Debug, Clone, Args)]
pub struct CatalogOpt {
    /// The catalog: `sqlite:PATH` or `postgres://user@host/db` (password from PGPASSWORD or
    /// ~/.pgpass). Default: $GYROCAL_CATALOG, else $XDG_DATA_HOME/gyrocal/catalog.sqlite.
    #[arg(long, value_name = "URL")]
    pub catalog: Option<String>,
}

/// Arguments of `gyrocal catalog`.
#[derive(Debug, Args)]
pub struct CatalogArgs {
    #[command(subcommand)]
    command: CatalogCommand,
}

#[derive(Debug, Subcommand)]
enum CatalogCommand {
    /// Add run directories to the catalog (again: a run already there is replaced). A
    /// directory that is not a run is skipped with a warning.
    Import {
        /// Run directories.
        #[arg(required = true, value_name = "DIR")]
        dirs: Vec<PathBuf>,
        #[command(flatten)]
        catalog: CatalogOpt,
    },
    /// Import every run directory under ROOT. On the SQLite catalog the catalog is emptied
    /// first (it then holds exactly what ROOT holds), and a damaged SQLite file is first moved
    /// aside (kept as FILE.damaged-<UTC time>); a shared PostgreSQL catalog is only added to.
    Rebuild {
        /// The directory holding the runs (searched recursively).
        #[arg(value_name = "ROOT")]
        root: PathBuf,
        #[command(flatten)]
        catalog: CatalogOpt,
    },
}

/// A catalog error for the user: a bad URL or a missing catalog file is bad input (exit 2);
/// anything else (unreachable, damaged, refused) is a failure (exit 1).
pub fn user_error(e: CatalogError) -> anyhow::Error {
    if matches!(e.kind(), ErrorKind::BadUrl | ErrorKind::NotFound) {
        BadInput(e.to_string()).into()
    } else {
        e.into()
    }
}

/// The catalog named by `opt`: `--catalog`, `$GYROCAL_CATALOG`, the station file's
/// `catalog`, the default file.
fn resolve(opt: &CatalogOpt) -> anyhow::Result<CatalogUrl> {
    // the station file's `catalog` (from $GYROCAL_STATION or the default file) comes after
    // --catalog and $GYROCAL_CATALOG; a station file that cannot be read is said, not fatal
    let station_catalog = match gyrocal_files::station::Station::resolve(None) {
        Ok(found) => found.and_then(|(_, s)| s.catalog),
        Err(e) => {
            eprintln!("gyrocal: warning: station: {e} (its catalog setting is not used)");
            None
        }
    };
    Catalog::resolve(opt.catalog.as_deref(), station_catalog.as_deref()).map_err(user_error)
}

fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    Ok(tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?)
}

/// A runtime and the catalog named by `opt`, open to be filled (created when missing).
fn open_to_fill(opt: &CatalogOpt) -> anyhow::Result<(tokio::runtime::Runtime, Catalog)> {
    let url = resolve(opt)?;
    let rt = runtime()?;
    let catalog = rt.block_on(Catalog::open(&url)).map_err(user_error)?;
    Ok((rt, catalog))
}

/// A runtime and the existing catalog named by `opt`, open to list from (`gyrocal runs`,
/// `gyrocal history`): creates nothing, refuses a damaged file.
pub fn open(opt: &CatalogOpt) -> anyhow::Result<(tokio::runtime::Runtime, Catalog)> {
    let url = resolve(opt)?;
    let rt = runtime()?;
    let catalog = rt
        .block_on(Catalog::open_existing(&url))
        .map_err(user_error)?;
    Ok((rt, catalog))
}

/// Before a rebuild of an SQLite catalog: a damaged file is moved aside (kept) and said, so
/// the rebuild starts from a new file; a sound or missing one is left as it is.
fn set_aside_if_damaged(
    rt: &tokio::runtime::Runtime,
    url: &CatalogUrl,
    root: &std::path::Path,
) -> anyhow::Result<()> {
    let CatalogUrl::Sqlite(path) = url else {
        return Ok(());
    };
    let Some(found) = rt
        .block_on(gyrocal_catalog::sqlite_damage(path))
        .map_err(user_error)?
    else {
        return Ok(());
    };
    let aside = gyrocal_catalog::set_aside(path).map_err(user_error)?;
    eprintln!(
        "gyrocal: the catalog {} is damaged ({found}): moved it aside to {} (kept, not deleted) and rebuilding it from the run directories under {}",
        path.display(),
        aside.display(),
        root.display()
    );
    Ok(())
}

/// Runs `gyrocal catalog`; the exit code.
pub fn run(args: &CatalogArgs) -> anyhow::Result<u8> {
    let (rt, catalog, dirs, clear) = match &args.command {
        CatalogCommand::Import { dirs, catalog } => {
            let (rt, catalog) = open_to_fill(catalog)?;
            (rt, catalog, dirs.clone(), false)
        }
        CatalogCommand::Rebuild { root, catalog } => {
            if !root.is_dir() {
                return Err(BadInput(format!("{}: no such directory", root.display())).into());
            }
            let url = resolve(catalog)?;
            let rt = runtime()?;
            set_aside_if_damaged(&rt, &url, root)?;
            let catalog = rt.block_on(Catalog::open(&url)).map_err(user_error)?;
            let clear = catalog.url().is_sqlite();
            (rt, catalog, gyrocal_catalog::find_run_dirs(root), clear)
        }
    };
    rt.block_on(async {
        if clear {
            catalog.clear().await.map_err(user_error)?;
        }
        let (mut imported, mut skipped) = (0usize, 0usize);
        for dir in &dirs {
            match catalog.import_dir(dir).await {
                Ok(_) => imported += 1,
                Err(e) if e.kind() == ErrorKind::NotARun => {
                    eprintln!("gyrocal: warning: skipped {}: {e}", dir.display());
                    skipped += 1;
                }
                Err(e) => return Err(user_error(e)),
            }
        }
        println!(
            "{imported} run(s) imported into {}{}",
            catalog.url(),
            if skipped > 0 {
                format!(", {skipped} directory(ies) skipped")
            } else {
                String::new()
            }
        );
        catalog.close().await;
        Ok(0)
    })
}
