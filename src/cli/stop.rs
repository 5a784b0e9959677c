//! Signals. Ctrl-C (SIGINT) and SIGTERM: the first asks the job to stop (inside the substep
//! under way, `mpm::Solver::stop_on`) and finish its outputs (bags, results, summary); a second
//! one exits at once. Either way the exit code follows the shell's convention, 128 plus the
//! signal: 130 for SIGINT, 143 for SIGTERM. SIGPIPE (output into a closed pipe) ends the
//! process quietly.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

use signal_hook::consts::{SIGINT, SIGTERM};
use signal_hook::flag;
use signal_hook::iterator::Signals;

/// The signals that stop a job.
const STOP_SIGNALS: [i32; 2] = [SIGINT, SIGTERM];
/// A process killed by signal `n` exits with `EXIT_CODE_SIGNAL_BASE + n` (POSIX shells).
const EXIT_CODE_SIGNAL_BASE: i32 = 128;
/// No signal received yet (signal numbers are positive).
const NO_SIGNAL: usize = 0;

/// The stop request of this process: set by the first SIGINT or SIGTERM.
struct StopRequest {
    /// True once a stop signal arrived; the jobs poll it every substep and inside substeps.
    flag: Arc<AtomicBool>,
    /// The first signal received, or [`NO_SIGNAL`].
    signal: Arc<AtomicUsize>,
    /// True once the user was told what the first signal does ([`tell_stopping`]).
    told: Arc<AtomicBool>,
}

static STOP: OnceLock<StopRequest> = OnceLock::new();

/// The flag the first SIGINT or SIGTERM sets (the handlers are installed on the first call).
/// A second signal exits at once with 128 plus its number.
pub fn stop_flag() -> anyhow::Result<Arc<AtomicBool>> {
    if let Some(stop) = STOP.get() {
        return Ok(stop.flag.clone());
    }
    let stop = StopRequest {
        flag: Arc::new(AtomicBool::new(false)),
        signal: Arc::new(AtomicUsize::new(NO_SIGNAL)),
        told: Arc::new(AtomicBool::new(false)),
    };
    for signal in STOP_SIGNALS {
        // In registration order: a signal that finds the flag already set exits at once; the
        // first one records which signal it was and sets the flag.
        flag::register_conditional_shutdown(
            signal,
            EXIT_CODE_SIGNAL_BASE + signal,
            stop.flag.clone(),
        )?;
        flag::register_usize(signal, stop.signal.clone(), signal as usize)?;
        flag::register(signal, stop.flag.clone())?;
    }
    // The handlers above only set flags; this thread tells the user what the first signal does
    // (and the job's end does, if the job ends before this thread runs: `tell_if_untold`).
    let mut signals = Signals::new(STOP_SIGNALS)?;
    let told = stop.told.clone();
    std::thread::spawn(move || {
        if let Some(signal) = signals.forever().next() {
            tell_stopping(&told, signal);
        }
    });
    let flag = stop.flag.clone();
    // A second caller racing this one gets the installed request; the handlers are
    // installed only here, on the main thread, before any job starts.
    let _ = STOP.set(stop);
    Ok(flag)
}

/// The first stop signal received (`SIGINT` or `SIGTERM`), if any.
pub fn received_signal() -> Option<i32> {
    let signal = STOP.get()?.signal.load(Ordering::SeqCst);
    (signal != NO_SIGNAL).then_some(signal as i32)
}

/// `SIGINT` or `SIGTERM`.
pub fn signal_name(signal: i32) -> Option<&'static str> {
    match signal {
        SIGINT => Some("SIGINT"),
        SIGTERM => Some("SIGTERM"),
        _ => None,
    }
}

/// The exit code of a job stopped by `signal`: 130 for SIGINT, 143 for SIGTERM.
pub fn exit_code(signal: i32) -> u8 {
    (EXIT_CODE_SIGNAL_BASE + signal) as u8
}

/// At the end of a job stopped by `signal`: tells the user what the signal did, if the
/// signal's thread has not yet (a job that ends within moments of the signal gets here first).
pub fn tell_if_untold(signal: i32) {
    if let Some(stop) = STOP.get() {
        tell_stopping(&stop.told, signal);
    }
}

/// Tells the user, once, that `signal` stops the job and finishes its outputs.
fn tell_stopping(told: &AtomicBool, signal: i32) {
    if !told.swap(true, Ordering::SeqCst) {
        eprintln!(
            "\n{}: stopping inside this substep and finishing the outputs (again to quit at \
             once)",
            signal_name(signal).unwrap_or("signal")
        );
    }
}

/// Gives SIGPIPE its default action back (the Rust runtime ignores it, so printing into a
/// closed pipe, as `sandstep analyze bag | head` does, would panic): the process ends quietly,
/// as command-line tools do.
pub fn end_quietly_on_closed_pipe() {
    // SAFETY: sets the disposition of one signal to the default, before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
