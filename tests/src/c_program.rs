//! Compiling the C test programs (`tests/c/*.c`) against the C library, with the system's C
//! compiler and the flags the library's `hexacomp.pc` gives, as a user's build would.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::library_dir;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// Writes `hexacomp.pc` for this build (the library in the build directory, the header in
/// `client-c/include`) from `client-c/hexacomp.pc.in` into `dir`, as an install step would.
fn write_pkg_config(dir: &Path) {
    let template = std::fs::read_to_string(workspace().join("client-c/hexacomp.pc.in")).unwrap();
    let filled = template
        .replace("@LIBDIR@", &library_dir().display().to_string())
        .replace(
            "@INCLUDEDIR@",
            &workspace().join("client-c/include").display().to_string(),
        )
        .replace("@VERSION@", env!("CARGO_PKG_VERSION"));
    assert!(
        !filled.contains('@'),
        "a placeholder left unfilled:\n{filled}"
    );
    std::fs::write(dir.join("hexacomp.pc"), filled).unwrap();
}

/// The words `pkg-config` prints for `args` with the `hexacomp.pc` of `dir`; `None` where
/// pkg-config is not installed, unless `HEXACOMP_REQUIRE_PKG_CONFIG` is set (as in CI), which
/// turns its absence into a failure.
fn pkg_config(dir: &Path, args: &[&str]) -> Option<Vec<String>> {
    let output = match Command::new("pkg-config")
        .env("PKG_CONFIG_PATH", dir)
        .args(args)
        .arg("hexacomp")
        .output()
    {
        Ok(output) => output,
        Err(e) if std::env::var_os("HEXACOMP_REQUIRE_PKG_CONFIG").is_none() => {
            eprintln!(
                "pkg-config not found ({e}): hexacomp.pc is not checked, the template's Libs.private and fixed paths used"
            );
            return None;
        }
        Err(e) => panic!("running pkg-config (Debian: apt-get install pkg-config): {e}"),
    };
    assert!(
        output.status.success(),
        "pkg-config {args:?} hexacomp failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    Some(
        String::from_utf8(output.stdout)
            .unwrap()
            .split_whitespace()
            .map(str::to_string)
            .collect(),
    )
}

/// The template's `Libs.private` words, for a machine without pkg-config: the one list of what
/// the static library needs from the system.
fn libs_private() -> Vec<String> {
    let template = std::fs::read_to_string(workspace().join("client-c/hexacomp.pc.in")).unwrap();
    let line = template
        .lines()
        .find_map(|l| l.strip_prefix("Libs.private:"))
        .expect("hexacomp.pc.in has a Libs.private line");
    line.split_whitespace().map(str::to_string).collect()
}

/// Compiles the C test program `tests/c/<source>` into `out` against the static or the shared
/// library, with the flags `hexacomp.pc` gives, and returns the executable's path.
pub fn compile(source: &str, out: &Path, shared: bool) -> PathBuf {
    // Installed, the package's hexacomp.pc is on pkg-config's own path: `out` holds none.
    if !crate::installed::installed() {
        write_pkg_config(out);
    }
    let stem = source.trim_end_matches(".c");
    let exe = out.join(if shared {
        format!("{stem}_shared")
    } else {
        format!("{stem}_static")
    });
    let mut cc = Command::new(std::env::var("CC").unwrap_or_else(|_| "cc".into()));
    let include = format!("-I{}", workspace().join("client-c/include").display());
    cc.args(["-std=c11", "-Wall", "-Wextra", "-Werror", "-O2"])
        .args(pkg_config(out, &["--cflags"]).unwrap_or_else(|| vec![include]))
        .arg(workspace().join("tests/c").join(source))
        .arg("-o")
        .arg(&exe);
    if shared {
        let libs = vec![
            format!("-L{}", library_dir().display()),
            "-lhexacomp".into(),
        ];
        cc.args(pkg_config(out, &["--libs"]).unwrap_or(libs));
        cc.arg(format!("-Wl,-rpath,{}", library_dir().display()));
    } else {
        // The archive itself, then what it needs from the system (`Libs.private`).
        cc.arg(library_dir().join("libhexacomp.a"));
        cc.args(
            pkg_config(out, &["--static", "--libs-only-l"])
                .unwrap_or_else(libs_private)
                .into_iter()
                .filter(|flag| flag != "-lhexacomp"),
        );
    }
    // The test programs use libm (sin, cos).
    cc.arg("-lm");
    let output = cc.output().expect("running the C compiler");
    assert!(
        output.status.success(),
        "compiling the C test program failed:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    exe
}

/// Runs the C test program `exe` against `service` (its arguments: the instance and the
/// service's process id, which the program may stop and continue) and returns what it printed;
/// a program that fails fails the test, with its output.
pub fn run_against(exe: &Path, service: &crate::ServiceProcess) -> String {
    let output = Command::new(exe)
        .arg(&service.instance)
        .arg(service.pid().to_string())
        .output()
        .unwrap_or_else(|e| panic!("running {}: {e}", exe.display()));
    let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(
        output.status.success(),
        "{} failed:\n{}\n{stdout}",
        exe.display(),
        String::from_utf8_lossy(&output.stderr)
    );
    stdout
}
