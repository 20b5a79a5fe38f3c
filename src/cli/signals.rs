//! SIGTERM (`kill`, Slurm at a job's time limit) and SIGINT (Ctrl-C) end a command cleanly: a thread waits for
//! them, removes what the run registered with [`jem::cleanup`] (the temporary files of writes under way, the
//! batch's locks, `jem degrade`'s temporary tree), says so on one line and exits with 128 + the signal's number
//! (143, 130), as the shell reports a process the signal killed. Files being renamed into place are finished
//! first (all of a pair's, or none), so a stopped run leaves no partial output and no lock: a rerun (a
//! resubmitted Slurm task, on any node) starts where it stopped.

use signal_hook::consts::{SIGINT, SIGTERM};

/// Starts the thread that handles SIGTERM and SIGINT (if the handlers cannot be installed, the signals keep their
/// default action).
pub(super) fn install() {
    let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGTERM, SIGINT]) else { return };
    std::thread::spawn(move || {
        if let Some(signal) = signals.forever().next() {
            // Held until the process ends: no write starts or finishes after the removal.
            let _held = jem::cleanup::remove_all();
            let name = if signal == SIGTERM { "SIGTERM" } else { "SIGINT" };
            note!("error: stopped by {name}; no partial output or lock left");
            std::process::exit(128 + signal);
        }
    });
}
