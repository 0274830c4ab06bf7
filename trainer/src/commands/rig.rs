//! The machine and the instrument a measuring command drives (`campaign`, `verify`): their
//! options, and building them.

use std::time::Duration;

use hexacomp_core::Geometry;
use hexacomp_core::fused::FusedModel;
use hexacomp_core::model::Model;
use hexacomp_lab::virtual_rig::{VirtualHardware, VirtualInstrument, VirtualMachine};
use hexacomp_measuring::campaign::{CampaignOptions, Instrument, Machine};
use hexacomp_measuring::command_instrument::CommandInstrument;
use hexacomp_measuring::followed_file::FollowedFile;
use hexacomp_measuring::linuxcnc_machine::{LinuxCncMachine, LinuxCncOptions};
use hexacomp_measuring::manual::{ManualInstrument, ManualMachine};
use hexacomp_virtual::{DEFAULT_MACHINE_SEED, ErrorModel, ErrorVariant, VirtualPlatform};

/// The machine, the instrument and how each pose is read.
#[derive(Debug, clap::Args)]
pub struct RigArgs {
    /// The machine to drive.
    #[arg(long, value_enum, default_value_t = MachineArg::Virtual)]
    machine: MachineArg,
    /// With --machine linuxcnc: the Python interpreter that has LinuxCNC's modules.
    ///
    /// The modules are `linuxcnc` and `hal`; Debian's packages install them for
    /// /usr/bin/python3.
    #[arg(
        help_heading = "Machine",
        long,
        default_value = "/usr/bin/python3",
        value_name = "PROGRAM"
    )]
    linuxcnc_python: String,
    /// With --machine linuxcnc: the HAL pins of the drives' commands, # for the joint
    /// number.
    ///
    /// Default: the hexacomp component's outputs hexacomp.0.motor-out-#, or motion's motor
    /// commands on a machine without the component.
    #[arg(help_heading = "Machine", long, value_name = "PINS")]
    linuxcnc_drive_pins: Option<String>,
    /// Seconds a move may take before the machine counts as stuck.
    #[arg(
        help_heading = "Machine",
        long,
        default_value_t = 600.0,
        value_name = "SECONDS"
    )]
    move_timeout: f64,
    /// The instrument that measures.
    #[arg(long, value_enum, default_value_t = InstrumentArg::Virtual)]
    instrument: InstrumentArg,
    /// With --instrument command: the program run for every reading.
    ///
    /// The program and fixed arguments (split as a shell does: quote a path with spaces)
    /// are run for every reading as `PROGRAM ARGS… ID X Y Z A B C READING`; it prints one
    /// CSV line, the targets p1x..pNz in the instrument's frame (empty cells: not seen) or,
    /// with --probe, the pose x,y,z,a,b,c (docs/commands.md, "campaign"). A program that cannot be
    /// started stops the run.
    #[arg(
        help_heading = "Instrument",
        long,
        value_name = "PROGRAM",
        required_if_eq("instrument", "command")
    )]
    instrument_command: Option<String>,
    /// With --instrument file: the file the tracker's software appends its readings to.
    ///
    /// One CSV line each as --instrument-command prints them (a fiducial's: x,y,z); lines
    /// appended while the machine moved are skipped (docs/commands.md, "campaign").
    #[arg(
        help_heading = "Instrument",
        long,
        value_name = "FILE",
        required_if_eq("instrument", "file")
    )]
    instrument_file: Option<std::path::PathBuf>,
    /// Seconds a reading may take.
    ///
    /// --instrument-command is then killed and retried; with --instrument file, the wait
    /// for the next line.
    #[arg(
        help_heading = "Instrument",
        long,
        default_value_t = 60.0,
        value_name = "SECONDS"
    )]
    command_timeout: f64,
    /// The instrument reports the platform's pose (a 6-DoF probe) instead of the targets.
    #[arg(help_heading = "Instrument", long)]
    probe: bool,
    /// Readings per pose, 1 to 1000 (outliers are rejected among four or more).
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u16).range(1..=1000))]
    readings: u16,
    /// Seconds between two readings (trackers need about 2 s per point for their stated
    /// accuracy).
    #[arg(
        help_heading = "Instrument",
        long,
        default_value_t = 0.0,
        value_name = "SECONDS"
    )]
    dwell: f64,
    /// Seconds to wait once the machine is in position, before the first reading (the structure
    /// and the drives settle).
    #[arg(
        help_heading = "Instrument",
        long,
        default_value_t = 0.0,
        value_name = "SECONDS"
    )]
    settle: f64,
    /// Attempts after a failed reading before the pose is recorded as a gap.
    #[arg(help_heading = "Instrument", long, default_value_t = CampaignOptions::default().retries)]
    retries: usize,
    /// Seed of the virtual machine's and instrument's noise.
    #[arg(help_heading = "Virtual machine", long, default_value_t = 1)]
    pub seed: u64,
    /// Seed that draws the virtual machine (its errors).
    #[arg(help_heading = "Virtual machine", long, default_value_t = DEFAULT_MACHINE_SEED)]
    machine_seed: u64,
    /// Error variant of the virtual machine.
    #[arg(help_heading = "Virtual machine", long, default_value_t = ErrorVariant::Paper, value_parser = super::named::<ErrorVariant>(ErrorVariant::ALL.map(ErrorVariant::name)))]
    error_variant: ErrorVariant,
    /// Where the virtual instrument stands: its pose `x,y,z,a,b,c` in the base frame (mm,
    /// degrees).
    ///
    /// Default: the base frame itself.
    #[arg(
        help_heading = "Virtual machine",
        long,
        value_name = "X,Y,Z,A,B,C",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    instrument_pose: Option<Vec<f64>>,
}

/// The machines a campaign can drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum MachineArg {
    /// The built-in virtual platform.
    Virtual,
    /// A running LinuxCNC (on, homed), through its Python interface: world coordinates, MDI
    /// G0 moves. With --instrument virtual the virtual platform stands in for its hardware,
    /// moved to what LinuxCNC commands the drives.
    Linuxcnc,
    /// Moved by the operator or another controller: each pose is shown, Enter on standard
    /// input confirms it.
    Manual,
}

/// The instruments a campaign can read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum InstrumentArg {
    /// The virtual platform's tracker.
    Virtual,
    /// A user's program (--instrument-command).
    Command,
    /// The operator types or pastes each reading on standard input.
    Manual,
    /// The lines the tracker's software appends to a file (--instrument-file), followed.
    File,
}

/// A machine and an instrument, built and checked.
pub struct Rig {
    /// The machine.
    pub machine: Box<dyn Machine>,
    /// The instrument.
    pub instrument: Box<dyn Instrument>,
    /// How each pose is read.
    pub options: CampaignOptions,
    /// What makes a record this rig's ([`RigArgs::settings`]).
    pub settings: String,
}

impl RigArgs {
    /// The file the instrument's readings are followed in, if any (an input: nothing may be
    /// written over it).
    pub fn instrument_file(&self) -> Option<&std::path::Path> {
        self.instrument_file.as_deref()
    }

    /// Whether the instrument reports poses (a probe) rather than targets.
    pub fn probe(&self) -> bool {
        self.probe
    }

    /// What `verify` and `check` measure with: the model the virtual machine's controller
    /// applies (read from `model`), and the instrument's pose in the base frame from the
    /// registration file `registration` (the identity without one; refused for the virtual
    /// instrument standing away from the base frame).
    pub fn compensation_and_frame(
        &self,
        geometry: &Geometry,
        model: Option<&std::path::Path>,
        registration: Option<&std::path::Path>,
    ) -> anyhow::Result<(Option<Model>, hexacomp_core::Pose)> {
        let compensation = model.map(|path| Model::load(path, geometry)).transpose()?;
        let registration = registration
            .map(hexacomp_formats::read_registration)
            .transpose()?;
        anyhow::ensure!(
            registration.is_some() || !self.virtual_instrument_away_from_base(),
            "the virtual instrument stands at --instrument-pose, away from the base frame: give \
             --registration (hexacomp-trainer register) to bring its measurements into the base \
             frame"
        );
        Ok((
            compensation,
            registration
                .map(|r| r.instrument_pose())
                .unwrap_or_default(),
        ))
    }

    /// Whether the instrument is the virtual platform's tracker, standing away from the base
    /// frame (its measurements need a registration).
    fn virtual_instrument_away_from_base(&self) -> bool {
        self.instrument == InstrumentArg::Virtual
            && self
                .instrument_pose
                .as_ref()
                .is_some_and(|p| p.iter().any(|v| *v != 0.0))
    }

    /// Whether the operator answers on standard input (a manual machine or instrument): then no
    /// progress bar is drawn over the prompts.
    fn interactive(&self) -> bool {
        self.machine == MachineArg::Manual
            || matches!(self.instrument, InstrumentArg::Manual | InstrumentArg::File)
    }

    /// The progress bar of `len` steps called `unit` (`configurations`, `attained poses`), with
    /// the time left; hidden when the operator answers prompts.
    pub fn progress_bar(&self, len: usize, unit: &str) -> indicatif::ProgressBar {
        let bar = if self.interactive() {
            indicatif::ProgressBar::hidden()
        } else {
            indicatif::ProgressBar::new(len as u64)
        };
        bar.with_style(
            indicatif::ProgressStyle::with_template(&format!(
                "{{bar:40}} {{pos}}/{{len}} {unit} ({{elapsed}}, about {{eta}} left)"
            ))
            .expect("a valid template"),
        )
    }

    /// A short description of the machine and the instrument for reports.
    pub fn description(&self) -> String {
        match self.instrument {
            InstrumentArg::Virtual => format!(
                "{:?} machine ({} errors, machine seed {}), virtual instrument{}",
                self.machine,
                self.error_variant,
                self.machine_seed,
                if self.probe { " (probe)" } else { "" }
            ),
            InstrumentArg::Command => format!(
                "{:?} machine, instrument command {:?}{}",
                self.machine,
                self.instrument_command.as_deref().unwrap_or_default(),
                if self.probe { " (probe)" } else { "" }
            ),
            InstrumentArg::Manual => format!(
                "{:?} machine, instrument read by the operator{}",
                self.machine,
                if self.probe { " (probe)" } else { "" }
            ),
            InstrumentArg::File => format!(
                "{:?} machine, instrument readings followed in {}{}",
                self.machine,
                self.instrument_file
                    .as_deref()
                    .unwrap_or(std::path::Path::new(""))
                    .display(),
                if self.probe { " (probe)" } else { "" }
            ),
        }
    }

    /// What makes a record this rig's: the machine, the instrument and the noise they draw, the
    /// geometry. Operational settings (readings, dwell, timeouts) may change between runs, and
    /// so may where the instrument stands (a tracker moved between runs is caught by the
    /// campaign's drift check and registered again).
    fn settings(&self, geometry: &Geometry, program: &[String]) -> String {
        let instrument = match self.instrument {
            InstrumentArg::Virtual => "virtual instrument".to_string(),
            InstrumentArg::Command => format!("command {program:?}"),
            InstrumentArg::Manual => "manual instrument".to_string(),
            InstrumentArg::File => "followed file instrument".to_string(),
        };
        format!(
            "machine {:?} (seed {}, machine seed {}, {} errors); {instrument}{}; geometry {}",
            self.machine,
            self.seed,
            self.machine_seed,
            self.error_variant,
            if self.probe { ", probe" } else { "" },
            geometry.fingerprint()
        )
    }

    /// A duration option in seconds.
    fn seconds(name: &str, value: f64) -> anyhow::Result<Duration> {
        Duration::try_from_secs_f64(value)
            .map_err(|_| anyhow::anyhow!("--{name} {value}: a number of seconds ≥ 0 is needed"))
    }

    /// The machine and the instrument, every option checked; `compensation`: the model the
    /// virtual machine's controller applies (`verify --model`).
    pub fn build(&self, geometry: &Geometry, compensation: Option<Model>) -> anyhow::Result<Rig> {
        let options = self.campaign_options()?;
        let timeout = Self::seconds("command-timeout", self.command_timeout)?;
        let program = self.instrument_program()?;
        anyhow::ensure!(
            self.instrument_file.is_none() || self.instrument == InstrumentArg::File,
            "--instrument-file is followed by --instrument file only"
        );
        let instrument_pose = super::instrument_pose(self.instrument_pose.as_deref())?;
        let model = ErrorModel::variant(self.error_variant);
        let platform = VirtualPlatform::new(geometry, &model, self.machine_seed, self.seed)?;
        let settings = self.settings(geometry, &program);
        let machine = self.machine(geometry, &platform, compensation)?;
        let instrument = self.instrument(geometry, platform, instrument_pose, program, timeout)?;
        Ok(Rig {
            machine,
            instrument,
            options,
            settings,
        })
    }

    /// How each pose is read: --readings, --dwell, --retries and --settle, checked.
    fn campaign_options(&self) -> anyhow::Result<CampaignOptions> {
        Ok(CampaignOptions {
            readings: usize::from(self.readings),
            dwell: Self::seconds("dwell", self.dwell)?,
            retries: self.retries,
            settle: Self::seconds("settle", self.settle)?,
            ..CampaignOptions::default()
        })
    }

    /// The words of --instrument-command with --instrument command (split as a shell does);
    /// none for the other instruments.
    fn instrument_program(&self) -> anyhow::Result<Vec<String>> {
        match self.instrument {
            InstrumentArg::Command => {
                let text = self.instrument_command.as_deref().unwrap_or_default();
                let words = shlex::split(text).ok_or_else(|| {
                    anyhow::anyhow!("--instrument-command {text:?}: unbalanced quotes")
                })?;
                anyhow::ensure!(!words.is_empty(), "--instrument-command is empty");
                Ok(words)
            }
            InstrumentArg::Virtual | InstrumentArg::Manual | InstrumentArg::File => Ok(Vec::new()),
        }
    }

    /// The machine of --machine; `platform` is the virtual machine (or LinuxCNC's hardware with
    /// the virtual instrument), `compensation` the model its controller applies.
    fn machine(
        &self,
        geometry: &Geometry,
        platform: &VirtualPlatform,
        compensation: Option<Model>,
    ) -> anyhow::Result<Box<dyn Machine>> {
        Ok(match self.machine {
            MachineArg::Virtual => Box::new(VirtualMachine {
                platform: platform.clone(),
                seed: self.seed,
                compensation: compensation.as_ref().map(FusedModel::new),
            }),
            MachineArg::Linuxcnc => {
                anyhow::ensure!(
                    compensation.is_none(),
                    "--model applies to the virtual machine: LinuxCNC compensates with what its \
                     hexacomp component's service serves"
                );
                self.linuxcnc(geometry, platform)?
            }
            MachineArg::Manual => {
                anyhow::ensure!(
                    compensation.is_none(),
                    "--model applies to the virtual machine"
                );
                anyhow::ensure!(
                    self.instrument != InstrumentArg::Virtual,
                    "the virtual instrument measures the virtual machine or LinuxCNC with the \
                     virtual platform as its hardware, not a machine moved by hand"
                );
                Box::new(ManualMachine {
                    geometry: geometry.clone(),
                })
            }
        })
    }

    /// A running LinuxCNC, connected; with the virtual instrument, `platform` stands in for its
    /// hardware.
    fn linuxcnc(
        &self,
        geometry: &Geometry,
        platform: &VirtualPlatform,
    ) -> anyhow::Result<Box<dyn Machine>> {
        let controller = Box::new(LinuxCncMachine::connect(
            geometry,
            &LinuxCncOptions {
                python: self.linuxcnc_python.clone(),
                drive_pins: self
                    .linuxcnc_drive_pins
                    .clone()
                    .unwrap_or_else(|| "hexacomp.0.motor-out-#".into()),
                drive_pins_given: self.linuxcnc_drive_pins.is_some(),
                move_timeout: Self::seconds("move-timeout", self.move_timeout)?,
            },
        )?);
        Ok(match self.instrument {
            InstrumentArg::Virtual => Box::new(VirtualHardware {
                controller,
                platform: platform.clone(),
                seed: self.seed,
            }),
            InstrumentArg::Command | InstrumentArg::Manual | InstrumentArg::File => controller,
        })
    }

    /// The instrument of --instrument: the virtual one on `platform`, standing at
    /// `instrument_pose` (base frame); `program` and `timeout` for a command or a followed file.
    fn instrument(
        &self,
        geometry: &Geometry,
        platform: VirtualPlatform,
        instrument_pose: hexacomp_core::Pose,
        program: Vec<String>,
        timeout: Duration,
    ) -> anyhow::Result<Box<dyn Instrument>> {
        Ok(match self.instrument {
            InstrumentArg::Virtual => Box::new(VirtualInstrument {
                platform,
                instrument: instrument_pose,
                probe: self.probe,
                seed: self.seed,
            }),
            InstrumentArg::Command => Box::new(CommandInstrument {
                program,
                targets: geometry.targets.len(),
                probe: self.probe,
                timeout,
            }),
            InstrumentArg::Manual => Box::new(ManualInstrument {
                targets: geometry.targets.len(),
                probe: self.probe,
            }),
            InstrumentArg::File => {
                let path = self.instrument_file.clone().unwrap_or_default();
                Box::new(
                    FollowedFile::open(path.clone(), geometry.targets.len(), self.probe, timeout)
                        .map_err(|e| anyhow::anyhow!("--instrument-file {}: {e}", path.display()))?,
                )
            }
        })
    }
}
