//! Termination requests for the `hexacomp-service` binary. SIGTERM and SIGINT are blocked in
//! every thread of the process and taken synchronously by the main thread (`sigtimedwait`):
//! a termination request is never lost to a later signal (systemd sends SIGCONT right after
//! SIGTERM), and no other thread's wait is interrupted by one. Every other signal keeps its
//! default action; SIGSTOP/SIGCONT (a debugger, strace) pause the service and never stop it.
//!
//! The library ([`crate::Service`]) installs nothing: a program that embeds the service decides
//! itself what stops it.

use std::time::Duration;

use crate::Error;

/// SIGTERM and SIGINT, blocked in the calling thread (and inherited by the threads it starts
/// afterwards) from [`TerminationSignals::block`] on.
#[derive(Debug)]
pub struct TerminationSignals {
    set: libc::sigset_t,
}

impl TerminationSignals {
    /// Blocks SIGTERM and SIGINT in the calling thread. Call it in the main thread before any
    /// other thread starts (before [`crate::Service::start`]), so that every thread inherits
    /// the mask and the signals stay pending until [`TerminationSignals::wait`] takes them.
    pub fn block() -> Result<Self, Error> {
        let set = signal_set(&[libc::SIGTERM, libc::SIGINT]);
        let ignored = signal_set(&[libc::SIGHUP, libc::SIGUSR1, libc::SIGUSR2]);
        for set in [&set, &ignored] {
            // SAFETY: `set` was initialised by `signal_set`; a null old mask is allowed.
            let failed =
                unsafe { libc::pthread_sigmask(libc::SIG_BLOCK, set, std::ptr::null_mut()) };
            if failed != 0 {
                return Err(Error::Signals(std::io::Error::from_raw_os_error(failed)));
            }
        }
        Ok(Self { set })
    }

    /// Unblocks SIGTERM and SIGINT in the calling (main) thread: from now on they take their
    /// default action and end the process at once (after a first one started a clean stop).
    pub fn deliver_from_now_on(&self) {
        // SAFETY: `self.set` was initialised by `signal_set`; a null old mask is allowed.
        unsafe { libc::pthread_sigmask(libc::SIG_UNBLOCK, &self.set, std::ptr::null_mut()) };
    }

    /// Waits up to `timeout` for SIGTERM or SIGINT: the signal's number, or `None` when none
    /// came (or the wait was interrupted by another signal, e.g. SIGCONT).
    pub fn wait(&self, timeout: Duration) -> Option<i32> {
        let timeout = libc::timespec {
            tv_sec: libc::time_t::try_from(timeout.as_secs()).unwrap_or(libc::time_t::MAX),
            // Below 10⁹: fits tv_nsec's type on every target.
            tv_nsec: timeout.subsec_nanos() as _,
        };
        // SAFETY: `self.set` was initialised by `block`; `timeout` lives for the call; the
        // siginfo pointer may be null.
        let signal = unsafe { libc::sigtimedwait(&self.set, std::ptr::null_mut(), &timeout) };
        (signal > 0).then_some(signal)
    }
}

/// The set of `signals`.
fn signal_set(signals: &[libc::c_int]) -> libc::sigset_t {
    // SAFETY: sigemptyset initialises the plain C struct before sigaddset uses it; both get a
    // pointer to it, and the signal numbers are valid.
    unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        for &signal in signals {
            libc::sigaddset(&mut set, signal);
        }
        set
    }
}

/// The name of a termination signal, for the log.
pub fn signal_name(signal: i32) -> &'static str {
    match signal {
        libc::SIGTERM => "SIGTERM",
        libc::SIGINT => "SIGINT",
        _ => "a signal",
    }
}
