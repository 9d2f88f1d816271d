//! One module per subcommand.
pub mod chart;
pub mod demo;
pub mod map;
pub mod observer;
pub mod plot;
