//! One module per `relief` subcommand.

pub mod bake;
pub mod bench;
pub mod demo;
pub mod frame;
pub mod load;
pub mod reference;
pub mod report;
