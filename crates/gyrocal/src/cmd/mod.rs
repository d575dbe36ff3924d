//! One module per subcommand.

pub mod allan;
pub mod catalog;
pub mod check;
pub mod completions;
pub mod fit;
pub mod history;
pub mod probe;
pub mod report;
pub mod run;
pub mod runs;
pub mod serve;
pub mod sim;
pub mod verify;

use std::io::IsTerminal as _;

/// Whether text on stderr may carry ANSI colour: only on a terminal, and never with
/// `NO_COLOR` set (https://no-color.org).
pub fn color_on_stderr() -> bool {
    std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty()) && std::io::stderr().is_terminal()
}
