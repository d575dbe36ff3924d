//! One module per subcommand.

pub mod check;
pub mod fit;
pub mod report;
pub mod run;
pub mod sim;
