//! The installed packages as the tests' subject (`HEXACOMP_INSTALLED=1`, set by `.ci/run` after
//! `apt-get install ./target/debian/*.deb`): the commands in `/usr/bin`, the C library in
//! `/usr/lib` with the system's `hexacomp.pc`, the HAL component LinuxCNC loads from its module
//! directory, and the service started as the systemd unit `hexacomp@.service` would start it:
//! its `ExecStart` line, as its `User=`, with its state directory, readiness notified.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Where the package installs the unit.
pub const UNIT_FILE: &str = "/usr/lib/systemd/system/hexacomp@.service";
/// The commands the package `hexacomp` installs in `/usr/bin`.
pub const PACKAGED_COMMANDS: [&str; 4] = [
    "hexacomp-service",
    "hexacomp-trainer",
    "hexacomp-client",
    "hexacomp-bench",
];
/// The state root systemd gives system units (`%S`).
pub const STATE_ROOT: &str = "/var/lib";

/// True when the tests are to use the installed packages instead of the build tree.
pub fn installed() -> bool {
    std::env::var_os("HEXACOMP_INSTALLED").is_some_and(|v| v == "1")
}

/// The settings of the unit's `[Service]` section the tests use (the rest is systemd's).
#[derive(Debug, Clone)]
pub struct ServiceUnit {
    settings: BTreeMap<String, String>,
    environment: BTreeMap<String, String>,
}

impl ServiceUnit {
    /// Reads the installed unit file; panics naming the file when it is missing or has no
    /// `ExecStart`, `User` or `StateDirectory`.
    pub fn installed() -> Self {
        let text = std::fs::read_to_string(UNIT_FILE)
            .unwrap_or_else(|e| panic!("{UNIT_FILE}: {e} (is the hexacomp package installed?)"));
        Self::parse(&text)
    }

    /// Parses the `[Service]` section of a unit file's text (`Key=Value` lines; `Environment=`
    /// with one quoted `NAME=value` assignment per line).
    pub fn parse(text: &str) -> Self {
        let mut settings = BTreeMap::new();
        let mut environment = BTreeMap::new();
        let mut in_service = false;
        for line in text.lines().map(str::trim) {
            if line.starts_with('[') {
                in_service = line == "[Service]";
                continue;
            }
            if !in_service || line.is_empty() || line.starts_with('#') {
                continue;
            }
            let (key, value) = line
                .split_once('=')
                .unwrap_or_else(|| panic!("unit line {line:?}"));
            if key == "Environment" {
                let words = shlex::split(value).unwrap_or_else(|| panic!("unit line {line:?}"));
                for word in words {
                    let (name, value) = word.split_once('=').expect("NAME=value");
                    environment.insert(name.to_string(), value.to_string());
                }
            } else {
                settings.insert(key.to_string(), value.to_string());
            }
        }
        for key in ["ExecStart", "User", "StateDirectory"] {
            assert!(settings.contains_key(key), "the unit has no {key}=");
        }
        Self {
            settings,
            environment,
        }
    }

    /// A setting of the `[Service]` section.
    pub fn get(&self, key: &str) -> Option<&str> {
        self.settings.get(key).map(String::as_str)
    }

    /// The user the unit runs the service as.
    pub fn user(&self) -> &str {
        &self.settings["User"]
    }

    /// The state directory of `instance` (`StateDirectory=` under [`STATE_ROOT`]).
    pub fn state_dir(&self, instance: &str) -> PathBuf {
        Path::new(STATE_ROOT).join(self.settings["StateDirectory"].replace("%i", instance))
    }

    /// The `ExecStart` command line for `instance`, as systemd expands it: `%i` the instance,
    /// `%S` the state root, a `$NAME` word the words of the unit's `Environment=` value.
    pub fn exec_start(&self, instance: &str) -> Vec<String> {
        let line = self.settings["ExecStart"]
            .replace("%i", instance)
            .replace("%S", STATE_ROOT);
        let words = shlex::split(&line).unwrap_or_else(|| panic!("ExecStart {line:?}"));
        words
            .into_iter()
            .flat_map(|word| match word.strip_prefix('$') {
                Some(name) => self
                    .environment
                    .get(name)
                    .unwrap_or_else(|| {
                        panic!("ExecStart names ${name}, which the unit does not set")
                    })
                    .split_whitespace()
                    .map(str::to_string)
                    .collect(),
                None => vec![word],
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_exec_start_line_is_expanded_as_systemd_does() {
        let unit = ServiceUnit::parse(
            "[Unit]\nDescription=x %i\n[Service]\nUser=hexacomp\nStateDirectory=hexacomp/%i\n\
             Environment=\"OPTIONS=--wait event\"\n\
             ExecStart=/usr/bin/hexacomp-service --instance %i --state-dir %S/hexacomp/%i $OPTIONS\n",
        );
        assert_eq!(
            unit.exec_start("mill"),
            [
                "/usr/bin/hexacomp-service",
                "--instance",
                "mill",
                "--state-dir",
                "/var/lib/hexacomp/mill",
                "--wait",
                "event"
            ]
        );
        assert_eq!(unit.user(), "hexacomp");
        assert_eq!(unit.state_dir("mill"), Path::new("/var/lib/hexacomp/mill"));
    }

    /// The repository's unit parses, and what the tests rely on is in it.
    #[test]
    fn the_repositorys_unit_starts_the_installed_service_with_its_state_directory() {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../packaging/systemd/hexacomp@.service");
        let unit = ServiceUnit::parse(&std::fs::read_to_string(path).unwrap());
        let line = unit.exec_start("mill");
        assert_eq!(line[0], "/usr/bin/hexacomp-service");
        let state = line
            .iter()
            .position(|w| w == "--state-dir")
            .expect("--state-dir");
        assert_eq!(Path::new(&line[state + 1]), unit.state_dir("mill"));
        assert_eq!(unit.get("Type"), Some("notify"));
        assert_eq!(unit.get("PrivateTmp"), Some("no"));
        assert_eq!(unit.get("RemoveIPC"), Some("no"));
    }
}
