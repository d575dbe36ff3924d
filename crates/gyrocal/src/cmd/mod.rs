//! One module per subcommand.

pub mod fit;
pub mod report;
