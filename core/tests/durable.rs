//! A replaced file survives a power loss: the system calls of `durable::replace_file`, traced
//! with strace, show the temporary file synced, renamed over the target, and then the directory
//! synced (without the last step the rename can be lost and the old file come back).
//!
//! Needs strace (`.ci/run` installs it and sets `HEXACOMP_REQUIRE_STRACE=1`, which turns a skip
//! into a failure).

use std::path::Path;
use std::process::Command;

use hexacomp_core::durable::replace_file;

/// Set in the traced child: the file it replaces.
const CHILD: &str = "HEXACOMP_DURABLE_CHILD";
const TEST: &str = "replacing_a_file_syncs_it_renames_it_and_syncs_its_directory";

/// One traced system call: `name(args) = result`.
struct Call {
    name: String,
    args: String,
    result: String,
}

fn parse(line: &str) -> Option<Call> {
    // "<pid> name(args)<padding> = result", strace's -f format.
    let call = line.split_once(' ')?.1.trim_start();
    let (name, rest) = call.split_once('(')?;
    let (args, result) = rest.rsplit_once(" = ")?;
    Some(Call {
        name: name.to_string(),
        args: args.trim_end().strip_suffix(')')?.to_string(),
        result: result.trim().to_string(),
    })
}

#[test]
fn replacing_a_file_syncs_it_renames_it_and_syncs_its_directory() {
    if let Some(path) = std::env::var_os(CHILD) {
        replace_file(Path::new(&path), b"the new content").unwrap();
        return;
    }
    // strace must exist and be allowed to trace (ptrace may be denied in a container).
    let traces = Command::new("strace")
        .args(["-o", "/dev/null", "true"])
        .status()
        .is_ok_and(|s| s.success());
    if !traces {
        assert!(
            std::env::var_os("HEXACOMP_REQUIRE_STRACE").is_none(),
            "strace is required (HEXACOMP_REQUIRE_STRACE) but not installed or not allowed to trace"
        );
        eprintln!("skipped: strace is not installed or not allowed to trace");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let directory = dir.path().to_str().unwrap().to_string();
    let target = format!("{directory}/model.hxm");
    std::fs::write(&target, b"the old content").unwrap();
    let log = dir.path().join("strace.log");
    let status = Command::new("strace")
        .args([
            "-f",
            "-qq",
            "-e",
            "trace=openat,rename,renameat,renameat2,fsync",
        ])
        .arg("-o")
        .arg(&log)
        .arg(std::env::current_exe().unwrap())
        .args(["--exact", TEST, "--test-threads=1"])
        .env(CHILD, &target)
        .status()
        .unwrap();
    assert!(status.success(), "the traced child failed");
    assert_eq!(std::fs::read(&target).unwrap(), b"the new content");
    let calls: Vec<Call> = std::fs::read_to_string(&log)
        .unwrap()
        .lines()
        .filter_map(parse)
        .collect();
    // The temporary is `.model.hxm.<random>.tmp` in the target's directory.
    let prefix = format!("\"{directory}/.model.hxm.");
    let temporary = calls
        .iter()
        .find_map(|c| {
            let start = c.args.find(&prefix)?;
            let name = &c.args[start + 1..];
            let end = name.find('"')?;
            let path = &name[..end];
            (c.name == "openat" && path.ends_with(".tmp")).then(|| path.to_string())
        })
        .expect("a temporary beside the target is created");
    let opened = |path: &str, from: usize| {
        calls[from..]
            .iter()
            .position(|c| c.name == "openat" && c.args.contains(&format!("\"{path}\"")))
            .map(|i| (from + i, calls[from + i].result.clone()))
    };
    let synced = |fd: &str, from: usize| {
        calls[from..]
            .iter()
            .position(|c| c.name == "fsync" && c.args == fd && c.result == "0")
            .map(|i| from + i)
    };
    let (created, temporary_fd) = opened(&temporary, 0).expect("the temporary file is created");
    let temporary_synced = synced(&temporary_fd, created).expect("the temporary file is synced");
    let renamed = calls
        .iter()
        .position(|c| {
            c.name.starts_with("rename")
                && c.args.contains(&format!("\"{temporary}\""))
                && c.args.contains(&format!("\"{target}\""))
                && c.result == "0"
        })
        .expect("the temporary file is renamed over the target");
    assert!(temporary_synced < renamed, "synced before the rename");
    let (_, directory_fd) =
        opened(&directory, renamed).expect("the directory is opened after the rename");
    synced(&directory_fd, renamed).expect("the directory is synced after the rename");
}
