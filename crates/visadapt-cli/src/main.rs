//! `visadapt`: the command-line front end of the visadapt library.
//!
//! Parses arguments, reports progress and errors, and calls the library; all the model
//! lives in the library crate.

mod cli;
mod commands;
mod graphics;
mod report;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    quiet_on_broken_pipe();
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn"))
        .format_target(false)
        .format_timestamp(None)
        .init();
    let cli = match cli::Cli::try_parse() {
        Ok(cli) => cli,
        // Usage errors: one line (clap's first), exit status 2 as clap does.
        Err(e) if e.use_stderr() => {
            let text = e.to_string();
            let line: Vec<&str> = text
                .lines()
                .take_while(|l| {
                    !l.starts_with("Usage:")
                        && !l.starts_with("For more information")
                        && !l.trim_start().starts_with("tip:")
                })
                .map(str::trim)
                .filter(|l| !l.is_empty())
                .collect();
            eprintln!("visadapt: {}", line.join(" "));
            return ExitCode::from(2);
        }
        // --help and --version.
        Err(e) => e.exit(),
    };
    let result = match cli.command {
        cli::Command::Map(args) => commands::map::run(args),
        cli::Command::Observer(args) => commands::observer::run(args),
        cli::Command::Timecourse(args) => commands::timecourse::run(args),
        cli::Command::Sequence(args) => commands::sequence::run(args),
        cli::Command::Video(args) => commands::video::run(args),
        cli::Command::Chart(args) => commands::chart::run(args),
        cli::Command::Demo(args) => commands::demo::run(args),
        cli::Command::Plot(args) => commands::plot::run(args),
        cli::Command::Visible(args) => commands::visible::run(args),
        cli::Command::Tolerance(args) => commands::tolerance::run(args),
        #[cfg(feature = "serve")]
        cli::Command::Serve(args) => commands::serve::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line: the context chain joined with ": ".
            eprintln!("visadapt: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// A reader that stops early (`visadapt observer 1 | head -1`) closes the pipe; `println!`
/// then panics with a broken-pipe error. That is not a failure of ours: exit quietly with
/// success, as Unix tools do, and keep the normal panic report for everything else.
fn quiet_on_broken_pipe() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let message = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if message.contains("failed printing to stdout") && message.contains("Broken pipe") {
            std::process::exit(0);
        }
        default(info);
    }));
}
