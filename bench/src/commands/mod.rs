//! The subcommands of `hexacomp-bench`.

pub mod batches;
pub mod compare;
pub mod compute;
pub mod demo;
pub mod path;
pub mod swap;
