//! docs/guide.md as a user runs it: every ```sh block, in order, in one empty directory, with
//! the workspace's binaries on PATH, on the virtual machine and tracker. The guide cannot drift
//! from the program: a command it shows that no longer runs fails this test.

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// The ```sh blocks of `markdown`, in order (the other fences — console, text — are not run).
fn shell_blocks(markdown: &str) -> Vec<String> {
    let mut blocks = Vec::new();
    let mut current: Option<Vec<&str>> = None;
    for line in markdown.lines() {
        match &mut current {
            None if line.trim_end() == "```sh" => current = Some(Vec::new()),
            Some(lines) if line.starts_with("```") => {
                blocks.push(lines.join("\n"));
                current = None;
            }
            Some(lines) => lines.push(line),
            None => {}
        }
    }
    assert!(current.is_none(), "docs/guide.md ends inside a ```sh block");
    blocks
}

fn guide() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/guide.md");
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The directory holding the workspace's binaries (built if needed).
fn binaries() -> PathBuf {
    hexacomp_tests::binary("hexacomp-trainer")
        .parent()
        .expect("a binary lies in a directory")
        .to_path_buf()
}

/// How long the guide may run: about 2 minutes here, on 2 busy cores with debug binaries.
const GUIDE_PATIENCE: Duration = Duration::from_secs(900);

/// The child's exit status, or `None` when it is still running after `patience`.
fn wait_at_most(child: &mut std::process::Child, patience: Duration) -> Option<ExitStatus> {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("waiting for the guide") {
            return Some(status);
        }
        if start.elapsed() > patience {
            return None;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn the_shell_blocks_are_read_in_order_and_other_fences_are_not() {
    let markdown = "text\n```sh\na\nb\n```\n```console\nc\n```\n```sh\nd\n```\n";
    assert_eq!(shell_blocks(markdown), ["a\nb", "d"]);
}

#[test]
fn every_command_of_the_guide_runs_as_written_on_the_virtual_machine() {
    let script = shell_blocks(&guide()).join("\n");
    // The steps of a calibration, each shown as a command that runs.
    for step in [
        "hexacomp-trainer geometry",
        "hexacomp-trainer plan",
        "hexacomp-trainer register",
        "hexacomp-trainer campaign",
        "hexacomp-trainer calibrate",
        "hexacomp-trainer deploy",
        "hexacomp-trainer verify",
        "hexacomp-trainer check",
    ] {
        assert!(script.contains(step), "the guide runs no `{step}`");
    }
    let dir = tempfile::tempdir().unwrap();
    let path = format!(
        "{}:{}",
        binaries().display(),
        std::env::var("PATH").unwrap_or_default()
    );
    // Its own process group: a service the guide starts in the background is stopped with it.
    // The output goes to files, not pipes: a background process that outlives a failed step
    // would hold a pipe open, and reading it to its end would wait for ever.
    let (stdout_path, stderr_path) = (dir.path().join("guide.out"), dir.path().join("guide.err"));
    let mut child = Command::new("bash")
        .args(["-euo", "pipefail", "-c", &script])
        .current_dir(dir.path())
        .env("PATH", path)
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&stdout_path).unwrap())
        .stderr(std::fs::File::create(&stderr_path).unwrap())
        .process_group(0)
        .spawn()
        .expect("running bash");
    let group = child.id() as i32;
    let status = wait_at_most(&mut child, GUIDE_PATIENCE);
    // SAFETY: kill has no memory preconditions; a negative pid names the guide's own process
    // group, which holds nothing but what the guide started (gone already, if it stopped all).
    unsafe { libc::kill(-group, libc::SIGKILL) };
    let stdout = std::fs::read_to_string(&stdout_path).unwrap_or_default();
    let stderr = std::fs::read_to_string(&stderr_path).unwrap_or_default();
    let status = status
        .unwrap_or_else(|| panic!("the guide ran past {GUIDE_PATIENCE:?}:\n{stdout}\n{stderr}"));
    assert!(
        status.success(),
        "the guide failed ({status}):\n--- stdout\n{stdout}\n--- stderr\n{stderr}"
    );
    // What the guide says happens, happened.
    let output = format!("{stdout}{stderr}");
    for promised in [
        "accepted as generation 1",
        "measured 50 configurations (0 recorded before, 0 gaps)",
        "still good",
    ] {
        assert!(
            output.contains(promised),
            "the guide did not say {promised:?}:\n{output}"
        );
    }
    for file in [
        "geometry.toml",
        "registration.toml",
        "campaign.csv",
        "calibration/model.hxm",
        "compensated.csv",
        "before.json",
        "after.json",
        "identified.toml",
    ] {
        assert!(
            dir.path().join(file).is_file(),
            "the guide wrote no {file}:\n{stdout}\n{stderr}"
        );
    }
}
