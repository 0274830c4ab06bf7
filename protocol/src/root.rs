//! iceoryx2's root directory, as far as the service and its clients must know it: who owns it.

/// Why a node could not be created when iceoryx2's root directory (`/tmp/iceoryx2/` unless its
/// configuration says otherwise) belongs to another user: iceoryx2 creates it 0750 for the user
/// that came first, and no other user may create nodes in it. A sentence to add to a node
/// creation error (service and clients), or nothing when the root is this process's user's,
/// absent, or the user is root.
pub fn foreign_root_hint() -> String {
    use std::os::unix::fs::MetadataExt;
    let root = iceoryx2::config::Config::global_config()
        .global
        .root_path()
        .to_string();
    let Ok(metadata) = std::fs::metadata(&root) else {
        return String::new();
    };
    // SAFETY: geteuid has no preconditions.
    let me = unsafe { libc::geteuid() };
    if me == 0 || metadata.uid() == me {
        return String::new();
    }
    format!(
        " (iceoryx2's root {root} belongs to user {} and this process runs as user {me}: \
         the service and its clients must run as the user that created it; if no iceoryx2 \
         program runs, remove it and start the service first)",
        metadata.uid()
    )
}
