//! Optional CPU pinning and real-time priority of the serving thread. Both are requests to the
//! operating system: when it refuses (no permission, no such CPU), the service warns and keeps
//! serving with the default scheduling.

use crate::Error;

/// Pins the calling thread to CPU `cpu`.
pub fn pin_to_cpu(cpu: usize) -> Result<(), Error> {
    if cpu >= libc::CPU_SETSIZE as usize {
        return Err(Error::Scheduling(format!(
            "CPU {cpu} is beyond the CPU set size"
        )));
    }
    // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU_SET writes inside it (cpu checked
    // above); sched_setaffinity reads it for the calling thread (pid 0).
    let result = unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
    };
    if result == 0 {
        Ok(())
    } else {
        Err(Error::Scheduling(format!(
            "pinning to CPU {cpu}: {}",
            std::io::Error::last_os_error()
        )))
    }
}

/// Gives the calling thread SCHED_FIFO priority `priority` (1–99).
pub fn set_realtime(priority: i32) -> Result<(), Error> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: param is a valid sched_param for the calling thread.
    let result =
        unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
    if result == 0 {
        Ok(())
    } else {
        Err(Error::Scheduling(format!(
            "SCHED_FIFO priority {priority}: {} (needs CAP_SYS_NICE or an rtprio limit)",
            std::io::Error::from_raw_os_error(result)
        )))
    }
}
