//! Subcommand implementations; each returns an error value, never panics on user input.

pub mod argv;
pub mod bridge;
pub mod bus;
pub mod bus_settings;
pub mod capability;
pub mod cell;
pub mod child;
pub mod common;
pub mod compare;
pub mod controller;
pub mod forecast;
pub mod model;
pub mod preview;
pub mod robot;
pub mod robustness;
pub mod run;
pub mod sim;
pub mod sweep_runner;

/// Any displayable cause of a command's failure, rendered once by `main`.
pub type BoxError = Box<dyn std::error::Error + Send + Sync>;

/// Error type of the command line.
pub type CliResult = Result<(), BoxError>;
