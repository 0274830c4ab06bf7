//! The workspace's layout as docs/design.md draws it: the crate graph in the design is the one
//! `cargo metadata` reports, no crate on a user's real-machine path depends on the lab or the
//! virtual platform, and the run-time core gains no dependency unnoticed.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

/// An arrow of the crate graph: `from` depends on `to` (short names, without `hexacomp-`).
type Edge = (String, String);

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate lies in the workspace")
        .to_path_buf()
}

/// The short name of a workspace package: `hexacomp-calibration` → `calibration`.
fn short(package: &str) -> String {
    package
        .strip_prefix("hexacomp-")
        .unwrap_or(package)
        .to_string()
}

/// Every workspace package's normal (not dev, not build) dependencies, by short name: the
/// arrows between the workspace's own crates, and each crate's dependencies of any kind.
struct Metadata {
    workspace_edges: BTreeSet<Edge>,
    dependencies: BTreeMap<String, BTreeSet<String>>,
}

fn metadata() -> Metadata {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let output = Command::new(cargo)
        .args(["metadata", "--format-version", "1", "--no-deps", "--locked"])
        .current_dir(workspace_root())
        .output()
        .expect("running cargo metadata");
    assert!(
        output.status.success(),
        "cargo metadata: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).expect("metadata JSON");
    let packages = json["packages"].as_array().expect("packages");
    let members: BTreeSet<String> = packages
        .iter()
        .map(|p| p["name"].as_str().expect("name").to_string())
        .collect();
    let mut workspace_edges = BTreeSet::new();
    let mut dependencies = BTreeMap::new();
    for package in packages {
        let from = short(package["name"].as_str().expect("name"));
        let normal: BTreeSet<String> = package["dependencies"]
            .as_array()
            .expect("dependencies")
            .iter()
            .filter(|d| d["kind"].is_null())
            .map(|d| d["name"].as_str().expect("dependency name").to_string())
            .collect();
        for to in normal.iter().filter(|d| members.contains(*d)) {
            workspace_edges.insert((from.clone(), short(to)));
        }
        dependencies.insert(from, normal);
    }
    Metadata {
        workspace_edges,
        dependencies,
    }
}

/// The arrows of the graph under docs/design.md's "## Crates": in its first ```text block, a
/// line `a → b, c` for each crate (`(none)` for no dependency; a parenthesis after the list is a
/// remark, and names that are not workspace crates, such as iceoryx2, are left to cargo).
fn documented_edges(members: &BTreeSet<String>) -> BTreeSet<Edge> {
    let path = workspace_root().join("docs/design.md");
    let design = std::fs::read_to_string(&path).expect("docs/design.md");
    let section = design
        .split("\n## Crates")
        .nth(1)
        .expect("docs/design.md has a section \"## Crates\"");
    let graph = section
        .split("```text")
        .nth(1)
        .and_then(|rest| rest.split("```").next())
        .expect("the Crates section holds a ```text graph");
    let mut edges = BTreeSet::new();
    for line in graph.lines() {
        let Some((from, to)) = line.split_once('→') else {
            continue;
        };
        let to = to.split('(').next().unwrap_or_default();
        for dependency in to.split(',').map(str::trim).filter(|d| !d.is_empty()) {
            if members.contains(dependency) {
                edges.insert((from.trim().to_string(), dependency.to_string()));
            }
        }
    }
    edges
}

#[test]
fn the_design_draws_the_crate_graph_cargo_reports() {
    let metadata = metadata();
    let actual = metadata.workspace_edges;
    let members: BTreeSet<String> = metadata.dependencies.keys().cloned().collect();
    let documented = documented_edges(&members);
    assert!(
        documented.len() > 20,
        "docs/design.md's graph was not read: {documented:?}"
    );
    let missing: Vec<_> = actual.difference(&documented).collect();
    let extra: Vec<_> = documented.difference(&actual).collect();
    assert!(
        missing.is_empty() && extra.is_empty(),
        "docs/design.md's crate graph differs from cargo metadata:\n  not drawn: {missing:?}\n  \
         drawn but not a dependency: {extra:?}"
    );
}

/// Every crate `from` reaches by normal dependencies, itself included.
fn reachable(edges: &BTreeSet<Edge>, from: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::from([from.to_string()]);
    let mut stack = vec![from.to_string()];
    while let Some(crate_name) = stack.pop() {
        for (_, to) in edges.iter().filter(|(f, _)| *f == crate_name) {
            if seen.insert(to.clone()) {
                stack.push(to.clone());
            }
        }
    }
    seen
}

/// The libraries and programs a real machine runs. The `hexacomp-trainer` binary composes every
/// library, the lab too (its `evaluate`, `survey` and `simulate` commands and `--machine
/// virtual`), but what it runs on a real machine is these libraries' code.
#[test]
fn the_real_machine_path_does_not_depend_on_the_lab_or_the_virtual_platform() {
    let edges = metadata().workspace_edges;
    let real_machine_path = [
        "core",
        "formats",
        "report",
        "calibration",
        "measuring",
        "iso9283",
        "protocol",
        "service",
        "client",
        "client-c",
        "client-cli",
    ];
    for crate_name in real_machine_path {
        let reached = reachable(&edges, crate_name);
        for forbidden in ["lab", "virtual"] {
            assert!(
                !reached.contains(forbidden),
                "{crate_name} depends on {forbidden} (through {reached:?}): a user's real-machine \
                 path must not"
            );
        }
    }
}

#[test]
fn the_core_depends_only_on_what_the_run_time_numerics_and_the_model_file_need() {
    let allowed = [
        "crc",
        "glam",
        "hexacomp-point-status",
        "nalgebra",
        "postcard",
        "rand",
        "rand_chacha",
        "rustix",
        "serde",
        "tempfile",
        "thiserror",
        "toml",
    ];
    let dependencies = &metadata().dependencies["core"];
    let unexpected: Vec<_> = dependencies
        .iter()
        .filter(|d| !allowed.contains(&d.as_str()))
        .collect();
    assert!(
        unexpected.is_empty(),
        "hexacomp-core gained {unexpected:?}: the run-time core must stay small (the service and \
         the C library link it); if it is needed, say why in the commit and add it here"
    );
}

/// The non-blank lines of `dir`'s Rust files, each cut at a top-level `#[cfg(test)]` module.
fn code_lines(dir: &Path) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    entries
        .map(|entry| entry.expect("a directory entry").path())
        .map(|path| {
            if path.is_dir() {
                return code_lines(&path);
            }
            if path.extension().is_none_or(|e| e != "rs") {
                return 0;
            }
            let text = std::fs::read_to_string(&path).expect("a source file");
            let code = text
                .split("\n#[cfg(test)]\nmod ")
                .next()
                .unwrap_or_default();
            code.lines().filter(|l| !l.trim().is_empty()).count()
        })
        .sum()
}

#[test]
fn no_crate_holds_more_than_30_percent_of_the_code() {
    let root = workspace_root();
    let metadata = metadata();
    let lines: BTreeMap<String, usize> = metadata
        .dependencies
        .keys()
        .map(|crate_name| {
            let dir = std::fs::read_dir(&root)
                .unwrap()
                .map(|e| e.unwrap().path())
                .find(|dir| {
                    std::fs::read_to_string(dir.join("Cargo.toml")).is_ok_and(|toml| {
                        toml.contains(&format!("[package]\nname = \"hexacomp-{crate_name}\"\n"))
                    })
                })
                .unwrap_or_else(|| panic!("no folder holds hexacomp-{crate_name}"));
            (crate_name.clone(), code_lines(&dir.join("src")))
        })
        .collect();
    let total: usize = lines.values().sum();
    assert!(total > 10_000, "the code was not read: {lines:?}");
    for (crate_name, count) in &lines {
        assert!(
            *count * 100 <= total * 30,
            "{crate_name} holds {count} of {total} lines of non-test code, over 30 %: split it by \
             job"
        );
    }
}
