//! `gyrocal completions SHELL` and `gyrocal man`: generated from the clap definitions (so they
//! never drift from the real options) with clap_complete and clap_mangen.

use std::io::Write as _;
use std::path::PathBuf;

use anyhow::Context as _;
use clap::{Args, CommandFactory as _};

use crate::BadInput;

/// Arguments of `gyrocal completions`.
#[derive(Debug, Args)]
pub struct CompletionsArgs {
    /// The shell: bash, zsh, fish, elvish or powershell.
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
}

/// Arguments of `gyrocal man`.
#[derive(Debug, Args)]
pub struct ManArgs {
    /// Write gyrocal.1 and one page per subcommand (gyrocal-run.1, ...) into DIR instead of
    /// printing gyrocal.1.
    #[arg(short = 'o', long, value_name = "DIR")]
    pub out: Option<PathBuf>,
}

/// Prints the completion script.
pub fn completions(args: &CompletionsArgs) -> anyhow::Result<()> {
    let mut cmd = crate::Cli::command();
    let mut out = Vec::new();
    clap_complete::generate(args.shell, &mut cmd, "gyrocal", &mut out);
    std::io::stdout()
        .write_all(&out)
        .context("writing the completion script")
}

/// Prints the man page or writes every page into a directory.
pub fn man(args: &ManArgs) -> anyhow::Result<()> {
    let cmd = crate::Cli::command();
    match &args.out {
        None => {
            let mut out = Vec::new();
            clap_mangen::Man::new(cmd)
                .render(&mut out)
                .context("rendering the man page")?;
            std::io::stdout()
                .write_all(&out)
                .context("writing the man page")
        }
        Some(dir) => {
            std::fs::create_dir_all(dir)
                .map_err(|e| BadInput(format!("cannot create {}: {e}", dir.display())))?;
            clap_mangen::generate_to(cmd, dir)
                .with_context(|| format!("writing the man pages into {}", dir.display()))
        }
    }
}
