//! One module per subcommand.
pub mod chart;
pub mod demo;
pub mod map;
pub mod observer;
pub mod plot;
pub mod sequence;
pub mod timecourse;
pub mod tolerance;
pub mod video;
pub mod visible;
