//! Manual pages and shell completions of hexacomp's commands, generated from their clap
//! definitions, so that what `man hexacomp-trainer-calibrate` says is what `--help` says.
//!
//! Every binary flattens [`GenerateArgs`] into its command line (`--generate-man DIR`,
//! `--generate-completions DIR`); `packaging/build-debs` calls them and the Debian package
//! installs the files. Each file is written whole or not at all.

use std::path::{Path, PathBuf};

use clap::CommandFactory;
use clap_complete::{Generator, Shell};

/// The shells whose completions are generated, with the file name each one's loader looks for
/// (bash-completion: the command's name; zsh: `_` and the name; fish: the name and `.fish`).
const SHELLS: [(Shell, &str, &str); 3] = [
    (Shell::Bash, "", ""),
    (Shell::Zsh, "_", ""),
    (Shell::Fish, "", ".fish"),
];

/// What can go wrong generating the files.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A page or script could not be rendered or written.
    #[error("writing {}: {source}", path.display())]
    Write {
        /// The file that was not written.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A completion script could not be rendered.
    #[error("rendering the {shell} completions of {command}: {source}")]
    Completions {
        /// The shell.
        shell: Shell,
        /// The command's name.
        command: String,
        /// Why.
        source: std::io::Error,
    },
}

/// The command-line options that make a binary write its manual pages or completions and exit,
/// instead of doing its job. Flatten it into the binary's `clap::Parser` and call
/// [`GenerateArgs::run_if_asked`] first thing in `main`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct GenerateArgs {
    /// Write this command's manual pages (section 1, roff: one page for the command and one
    /// per subcommand, named like `hexacomp-trainer-calibrate.1`) into DIR and exit.
    #[arg(long, value_name = "DIR", exclusive = true, help_heading = "Packaging")]
    pub generate_man: Option<PathBuf>,
    /// Write this command's completion scripts for bash (DIR/NAME), zsh (DIR/_NAME) and fish
    /// (DIR/NAME.fish) into DIR and exit.
    #[arg(long, value_name = "DIR", exclusive = true, help_heading = "Packaging")]
    pub generate_completions: Option<PathBuf>,
}

impl GenerateArgs {
    /// True when one of the options was given: the caller generates and exits instead of
    /// running.
    pub fn asked(&self) -> bool {
        self.generate_man.is_some() || self.generate_completions.is_some()
    }

    /// Writes what was asked for about the command `C`; `Ok(false)` when nothing was asked.
    pub fn run_if_asked<C: CommandFactory>(&self) -> Result<bool, Error> {
        if let Some(dir) = &self.generate_man {
            write_man_pages(C::command(), dir)?;
        }
        if let Some(dir) = &self.generate_completions {
            write_completions(C::command(), dir)?;
        }
        Ok(self.asked())
    }

    /// For a command whose subcommand is optional only so that these options can stand alone:
    /// gives the subcommand, or exits: with status 0 once what was asked for is written; with
    /// status 1 and the error on standard error when it could not be; with clap's "requires a
    /// subcommand" error and status 2 without either, as a required subcommand would; with a
    /// usage error and status 2 with both.
    pub fn subcommand_or_exit<C: CommandFactory, T>(&self, command: Option<T>) -> T {
        if self.asked() && command.is_some() {
            // `exclusive` covers options, not subcommands.
            C::command()
                .error(
                    clap::error::ErrorKind::ArgumentConflict,
                    "--generate-man and --generate-completions take no subcommand",
                )
                .exit()
        }
        match self.run_if_asked::<C>() {
            Ok(true) => std::process::exit(0),
            Ok(false) => {}
            Err(e) => {
                eprintln!("error: {e}");
                std::process::exit(1)
            }
        }
        match command {
            Some(command) => command,
            None => {
                let mut cli = C::command();
                let names: Vec<_> = cli
                    .get_subcommands()
                    .filter(|s| !s.is_hide_set())
                    .map(|s| s.get_name().to_owned())
                    .collect();
                cli.error(
                    clap::error::ErrorKind::MissingSubcommand,
                    format!("a subcommand is required: one of {}", names.join(", ")),
                )
                .exit()
            }
        }
    }
}

/// Writes the manual pages of `command` and of each of its visible subcommands (recursively)
/// into `dir`, which must exist; returns the files written.
pub fn write_man_pages(command: clap::Command, dir: &Path) -> Result<Vec<PathBuf>, Error> {
    let mut command = command.disable_help_subcommand(true);
    // Gives each subcommand its display name `parent-sub`, which names its page.
    command.build();
    let mut written = Vec::new();
    write_pages_of(command, dir, &mut written)?;
    Ok(written)
}

fn write_pages_of(
    command: clap::Command,
    dir: &Path,
    written: &mut Vec<PathBuf>,
) -> Result<(), Error> {
    for sub in command.get_subcommands().filter(|s| !s.is_hide_set()) {
        write_pages_of(sub.clone(), dir, written)?;
    }
    let page = clap_mangen::Man::new(command);
    let path = dir.join(page.get_filename());
    let mut roff = Vec::new();
    page.render(&mut roff)
        .and_then(|()| hexacomp_core::durable::replace_file(&path, &roff))
        .map_err(|source| Error::Write {
            path: path.clone(),
            source,
        })?;
    written.push(path);
    Ok(())
}

/// Writes the bash, zsh and fish completion scripts of `command` into `dir`, which must exist,
/// under the names the shells' loaders look for; returns the files written.
pub fn write_completions(mut command: clap::Command, dir: &Path) -> Result<Vec<PathBuf>, Error> {
    let name = command.get_name().to_owned();
    command.set_bin_name(&name);
    command.build();
    let mut written = Vec::new();
    for (shell, prefix, suffix) in SHELLS {
        let mut script = Vec::new();
        shell
            .try_generate(&command, &mut script)
            .map_err(|source| Error::Completions {
                shell,
                command: name.clone(),
                source,
            })?;
        let path = dir.join(format!("{prefix}{name}{suffix}"));
        hexacomp_core::durable::replace_file(&path, &script).map_err(|source| Error::Write {
            path: path.clone(),
            source,
        })?;
        written.push(path);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A command with a visible and a hidden subcommand, as the binaries have.
    fn sample() -> clap::Command {
        clap::Command::new("hexacomp-sample")
            .version("1.2.3")
            .about("Samples things.")
            .arg(
                clap::Arg::new("instance")
                    .long("instance")
                    .help("Instance name."),
            )
            .subcommand(
                clap::Command::new("calibrate").about("Calibrates.").arg(
                    clap::Arg::new("out-dir")
                        .long("out-dir")
                        .help("Where to write."),
                ),
            )
            .subcommand(clap::Command::new("serve-echo").hide(true))
    }

    #[test]
    fn one_page_per_visible_command_named_after_its_parent() {
        let dir = tempfile::tempdir().unwrap();
        let mut written = write_man_pages(sample(), dir.path()).unwrap();
        written.sort();
        let names: Vec<_> = written
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["hexacomp-sample-calibrate.1", "hexacomp-sample.1"]);
        let page = std::fs::read_to_string(dir.path().join("hexacomp-sample-calibrate.1")).unwrap();
        assert!(page.starts_with(".ie \\n(.g .ds Aq"), "roff: {page}");
        assert!(page.contains(".TH hexacomp-sample-calibrate 1"), "{page}");
        assert!(page.contains("Where to write."), "{page}");
        let top = std::fs::read_to_string(dir.path().join("hexacomp-sample.1")).unwrap();
        assert!(top.contains("Instance name."), "{top}");
        assert!(
            !top.contains("serve\\-echo"),
            "a hidden command is listed: {top}"
        );
    }

    #[test]
    fn completions_under_the_names_the_shells_load() {
        let dir = tempfile::tempdir().unwrap();
        write_completions(sample(), dir.path()).unwrap();
        let bash = std::fs::read_to_string(dir.path().join("hexacomp-sample")).unwrap();
        assert!(
            bash.lines()
                .any(|l| l.trim_start().starts_with("complete -F")
                    && l.ends_with(" hexacomp-sample")),
            "{bash}"
        );
        assert!(bash.contains("--out-dir"), "{bash}");
        let zsh = std::fs::read_to_string(dir.path().join("_hexacomp-sample")).unwrap();
        assert!(zsh.starts_with("#compdef hexacomp-sample"), "{zsh}");
        let fish = std::fs::read_to_string(dir.path().join("hexacomp-sample.fish")).unwrap();
        assert!(fish.contains("complete -c hexacomp-sample"), "{fish}");
    }

    #[test]
    fn a_missing_directory_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("no-such-dir");
        let error = write_man_pages(sample(), &missing).unwrap_err();
        assert!(error.to_string().contains("no-such-dir"), "{error}");
        assert!(!missing.exists());
    }

    #[test]
    fn generate_options_stand_alone() {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            generate: GenerateArgs,
            #[arg(long)]
            instance: Option<String>,
        }
        use clap::Parser;
        let parsed = Cli::try_parse_from(["x", "--generate-man", "d"]).unwrap();
        assert!(parsed.generate.asked());
        assert!(Cli::try_parse_from(["x", "--generate-man", "d", "--instance", "a"]).is_err());
        assert!(!Cli::try_parse_from(["x"]).unwrap().generate.asked());
    }
}
