//! SIGINT (Ctrl-C) and SIGTERM (`kill`, a batch system's time limit) during `granite run`: the
//! first asks the run to stop cleanly at its next step (outputs and the script's checkpoint
//! written, status `interrupted`); a second one ends the process at once.

use std::sync::atomic::{AtomicI32, Ordering};

/// The signal that asked the run to stop, 0 while none did.
pub static STOP: AtomicI32 = AtomicI32::new(0);

#[cfg(unix)]
extern "C" fn on_signal(signal: libc::c_int) {
    if STOP.swap(signal, Ordering::SeqCst) != 0 {
        // Only async-signal-safe calls here: write(2) and _exit(2).
        let msg = b"\ngranite: a second signal: stopped at once, outputs as they are\n";
        unsafe {
            libc::write(2, msg.as_ptr().cast(), msg.len());
            libc::_exit(128 + signal);
        }
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
    Ok(&STOP)
}

/// The signal that stopped the run, if one did.
pub fn received() -> Option<i32> {
    Some(STOP.load(Ordering::SeqCst)).filter(|&s| s != 0)
}
