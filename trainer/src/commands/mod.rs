//! One module per subcommand.

pub mod geometry;
pub mod survey;
