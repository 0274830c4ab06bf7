//! What the service tells systemd when it runs under it: that it serves (`sd_notify(3)`, for a
//! unit of `Type=notify`, so that LinuxCNC's unit is started only once compensation is
//! available) and how severe each log line is (the `<N>` prefixes of `sd-daemon(3)`, which the
//! journal turns into priorities). Outside systemd both are nothing: `NOTIFY_SOCKET` and
//! `JOURNAL_STREAM` are not set.

use std::os::fd::AsFd;
use std::os::unix::fs::MetadataExt;

use tracing::Level;

/// Tells the service manager the service is serving `instance` (`READY=1` and a `STATUS=` line
/// `systemctl status` shows; the model's generation, which deploys change, is in
/// `hexacomp-client status`). A failure to send is logged, not fatal: serving goes on, and the
/// manager, which never heard, times the start out by itself.
pub fn notify_serving(instance: &str) {
    let status = format!("serving instance {instance}");
    notify(&[
        sd_notify::NotifyState::Ready,
        sd_notify::NotifyState::Status(&status),
    ]);
}

/// Tells the service manager the service is stopping (`STOPPING=1`).
pub fn notify_stopping() {
    notify(&[sd_notify::NotifyState::Stopping]);
}

fn notify(states: &[sd_notify::NotifyState]) {
    if let Err(e) = sd_notify::notify(states) {
        let socket = std::env::var_os("NOTIFY_SOCKET").unwrap_or_default();
        tracing::error!(
            "could not notify the service manager at NOTIFY_SOCKET={}: {e}",
            socket.to_string_lossy()
        );
    }
}

/// True when standard error is the journal's stream: `JOURNAL_STREAM` (set by systemd for a
/// unit whose output goes to the journal) names the device and inode of standard error. A
/// variable inherited by a process whose standard error was redirected elsewhere names another
/// file, which gives false.
pub fn stderr_is_journal() -> bool {
    let Some(stream) = std::env::var_os("JOURNAL_STREAM") else {
        return false;
    };
    let Some((device, inode)) = stream.to_str().and_then(|s| s.split_once(':')) else {
        return false;
    };
    // A duplicate of the descriptor, so that the `File` made of it closes the duplicate only.
    let Ok(stderr) = std::io::stderr().as_fd().try_clone_to_owned() else {
        return false;
    };
    let Ok(metadata) = std::fs::File::from(stderr).metadata() else {
        return false;
    };
    device.parse() == Ok(metadata.dev()) && inode.parse() == Ok(metadata.ino())
}

/// The syslog priority `sd-daemon(3)` prefixes a line with for a `tracing` level (3 error, 4
/// warning, 6 info, 7 debug; trace is debug too).
pub fn syslog_priority(level: Level) -> u8 {
    match level {
        Level::ERROR => 3,
        Level::WARN => 4,
        Level::INFO => 6,
        Level::DEBUG | Level::TRACE => 7,
    }
}

/// A log format that puts each event's priority prefix (`<6>`) before the format `F` writes,
/// for the journal (which keeps its own timestamps: use `F` without time).
pub struct PriorityPrefixed<F>(pub F);

impl<S, N, F> tracing_subscriber::fmt::FormatEvent<S, N> for PriorityPrefixed<F>
where
    S: tracing::Subscriber + for<'a> tracing_subscriber::registry::LookupSpan<'a>,
    N: for<'a> tracing_subscriber::fmt::FormatFields<'a> + 'static,
    F: tracing_subscriber::fmt::FormatEvent<S, N>,
{
    fn format_event(
        &self,
        context: &tracing_subscriber::fmt::FmtContext<'_, S, N>,
        mut writer: tracing_subscriber::fmt::format::Writer<'_>,
        event: &tracing::Event<'_>,
    ) -> std::fmt::Result {
        write!(writer, "<{}>", syslog_priority(*event.metadata().level()))?;
        self.0.format_event(context, writer, event)
    }
}
