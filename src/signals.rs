//! SIGINT (Ctrl-C) and SIGTERM (`kill`, a batch system's time limit) during `granite run`: the
//! first asks the run to stop cleanly at its next step (outputs and the script's checkpoint
//! written, status `interrupted`); a second one, a second or more later, ends the process at
//! once. Signals within that second are one request sent twice: `timeout -s INT` signals the
//! process and then its whole group, a terminal's Ctrl-C reaches every process of the job.

use std::sync::atomic::{AtomicI32, AtomicI64, Ordering};

/// The signal that asked the run to stop, 0 while none did.
pub static STOP: AtomicI32 = AtomicI32::new(0);

/// When the first signal came (milliseconds of the monotonic clock).
static FIRST_AT_MS: AtomicI64 = AtomicI64::new(0);

/// Signals closer than this to the first one repeat it.
const REPEAT_WINDOW_MS: i64 = 1000;

#[cfg(unix)]
// time_t and c_long are 32-bit on some targets.
#[allow(clippy::unnecessary_cast)]
fn monotonic_ms() -> i64 {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime is async-signal-safe and writes only `t`.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut t) };
    t.tv_sec as i64 * 1000 + t.tv_nsec as i64 / 1_000_000
}

#[cfg(unix)]
extern "C" fn on_signal(signal: libc::c_int) {
    let now = monotonic_ms();
    if STOP.compare_exchange(0, signal, Ordering::SeqCst, Ordering::SeqCst).is_ok() {
        FIRST_AT_MS.store(now, Ordering::SeqCst);
        return;
    }
    if now - FIRST_AT_MS.load(Ordering::SeqCst) < REPEAT_WINDOW_MS {
        return;
    }
    // Only async-signal-safe calls here: write(2) and _exit(2).
    let msg = b"\ngranite: a second signal: stopped at once, outputs as they are\n";
    unsafe {
        libc::write(2, msg.as_ptr().cast(), msg.len());
        libc::_exit(128 + signal);
    }
}

/// Installs the handler for SIGINT and SIGTERM; the flag a run watches.
pub fn install() -> Result<&'static AtomicI32, String> {
    #[cfg(unix)]
    for signal in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: a zeroed sigaction is a valid value; the handler only touches an atomic and
        // calls async-signal-safe functions.
        let installed = unsafe {
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = on_signal as extern "C" fn(libc::c_int) as usize;
            action.sa_flags = libc::SA_RESTART;
            libc::sigemptyset(&mut action.sa_mask);
            libc::sigaction(signal, &action, std::ptr::null_mut())
        };
        if installed != 0 {
            return Err(format!("cannot handle signal {signal}: {}", std::io::Error::last_os_error()));
        }
    }
    // A file-size limit (`ulimit -f`) makes the write that crosses it fail with an error naming
    // the file, instead of killing the process in the middle of it.
    #[cfg(unix)]
    // SAFETY: ignoring a signal installs no code.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
    Ok(&STOP)
}

/// The signal that stopped the run, if one did.
pub fn received() -> Option<i32> {
    Some(STOP.load(Ordering::SeqCst)).filter(|&s| s != 0)
}
