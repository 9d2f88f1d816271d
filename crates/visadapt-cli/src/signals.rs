//! Interruption: what `SIGINT` (Ctrl-C) and `SIGTERM` do to a running command.
//!
//! Every output is written through a temporary file that becomes the named file only when
//! complete (the library's `io::output`). On Linux that file is unnamed, so an interruption
//! of any kind (even `SIGKILL`) leaves nothing behind; where it is a named
//! `.visadapt-*.tmp` file, the handler installed here deletes every such file of the
//! process, keeps any other from being created or moved into place, and ends the process
//! with the shell's convention for a signal: exit status 130 after `SIGINT`, 143 after
//! `SIGTERM` (128 + the signal's number). Files already complete stay as they are.
//!
//! The handler is a thread woken by `signal-hook`'s self-pipe, not code run inside the
//! signal handler, so it may take locks and call the file system. `serve` does not install
//! it: the viewer stops gracefully on the same signals (exit 0) through tokio.

/// Install the handler for the rest of the process. Failing to install it (no threads, a
/// signal the platform forbids) is not fatal: the signals then keep their default action.
#[cfg(unix)]
pub fn remove_outputs_in_flight_on_interrupt() {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM]) else {
        log::warn!("cannot handle SIGINT/SIGTERM: an interruption may leave temporary files");
        return;
    };
    let spawned = std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            if let Some(signal) = signals.forever().next() {
                visadapt::io::output::remove_in_flight_files();
                std::process::exit(128 + signal);
            }
        });
    if spawned.is_err() {
        log::warn!("cannot handle SIGINT/SIGTERM: an interruption may leave temporary files");
    }
}

/// Elsewhere the signals keep their default action.
#[cfg(not(unix))]
pub fn remove_outputs_in_flight_on_interrupt() {}
