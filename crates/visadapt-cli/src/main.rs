//! `visadapt`: the command-line front end of the visadapt library.
//!
//! Parses arguments, reports progress and errors, and calls the library; all the model
//! lives in the library crate.

mod cli;
mod commands;
mod graphics;
mod numbers;
mod report;
mod signals;

use clap::Parser;
use std::process::ExitCode;

/// Image-sized buffers on transparent huge pages (`visadapt::pages`): a 1080p `map` spent
/// half its CPU time in page faults on 4 KiB pages.
#[global_allocator]
static ALLOCATOR: visadapt::pages::HugePages = visadapt::pages::HugePages;

fn main() -> ExitCode {
    quiet_on_broken_pipe();
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn"))
        .format_target(false)
        .format_timestamp(None)
        .init();
    // Usage errors are clap's own: the message, its "tip:" for a near miss, the Usage line
    // and the pointer to --help, exit status 2. `visadapt` alone prints the help. The
    // one-line rule is for run-time errors, below.
    let cli = cli::Cli::parse();
    if let Err(e) = cli.check() {
        e.exit();
    }
    // Ctrl-C and SIGTERM remove the outputs in flight and exit 130/143 (`signals`), except
    // in the viewer, which stops gracefully on them by itself.
    #[cfg(feature = "serve")]
    let serving = matches!(cli.command, cli::Command::Serve(_));
    #[cfg(not(feature = "serve"))]
    let serving = false;
    if !serving {
        signals::remove_outputs_in_flight_on_interrupt();
    }
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
