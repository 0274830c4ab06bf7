//! Reading the hexapod geometry of a LinuxCNC configuration (kinematics `genhexkins`).
//!
//! LinuxCNC keeps a hexapod's joint centres in HAL parameters (`setp genhexkins.base.N.x …`,
//! `genhexkins.platform.N.{x,y,z}`, machine units, in HAL files named by the ini's `[HAL]HALFILE`),
//! its units in `[TRAJ]LINEAR_UNITS`, its home pose in `[TRAJ]HOME` and the joint (leg) travel in
//! `[JOINT_N]MIN_LIMIT`/`MAX_LIMIT`. genhexkins and hexacomp share the pose convention
//! (`q_i = |p + Rz(c)·Ry(b)·Rx(a)·a_i − b_i|`), so converting is a change of units: this module
//! turns those numbers into a [`Geometry`] in mm. What LinuxCNC does not know — the task workspace
//! and the measured targets — comes from [`ConversionOptions`].

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::DVec3;
use hexacomp_core::Geometry;
use hexacomp_core::geometry::{LEGS, Workspace};

use crate::error::{Error, Result};

/// The numbers of a LinuxCNC hexapod configuration, in its machine units.
#[derive(Debug, Clone, PartialEq)]
pub struct LinuxCncHexapod {
    /// `[EMC]MACHINE`, or the ini file's stem.
    pub machine: String,
    /// Millimetres per machine length unit (`[TRAJ]LINEAR_UNITS`): 1 for mm, 25.4 for inch.
    pub mm_per_unit: f64,
    /// Base joint centres `genhexkins.base.N.{x,y,z}`, machine units, base frame.
    pub base_joints: [DVec3; LEGS],
    /// Platform joint centres `genhexkins.platform.N.{x,y,z}`, machine units, platform frame.
    pub platform_joints: [DVec3; LEGS],
    /// `[TRAJ]HOME` `[x, y, z, a, b, c]`, machine units and degrees.
    pub home: [f64; 6],
    /// The joint travel every leg allows (the intersection of `[JOINT_0..5]MIN_LIMIT..MAX_LIMIT`),
    /// machine units.
    pub joint_limits: [f64; 2],
}

/// What a LinuxCNC configuration does not say, for [`LinuxCncHexapod::to_geometry`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ConversionOptions {
    /// Leg stroke `[min, max]`, mm; default: the ini's joint limits.
    pub leg_range: Option<[f64; 2]>,
    /// Task workspace, mm and degrees; default: see [`default_workspace`].
    pub workspace: Option<Workspace>,
}

impl LinuxCncHexapod {
    /// Reads the ini file and the HAL files its `[HAL]HALFILE` entries name (relative to the ini's
    /// directory; `LIB:` files and Tcl files are LinuxCNC's own and hold no hexapod geometry).
    pub fn read(ini_path: &Path) -> Result<Self> {
        let ini = Ini::read(ini_path)?;
        let mut parameters = BTreeMap::new();
        for path in hal_files_of(ini_path, &ini) {
            let text = read_text(&path)?;
            collect_setp(&text, &ini, &mut parameters).map_err(|p| config_error(&path, p))?;
        }
        Self::from_parts(ini_path, &ini, &parameters)
    }

    /// The configuration of `ini` (read from `path`) and the `setp` values of its HAL files.
    fn from_parts(path: &Path, ini: &Ini, hal: &BTreeMap<String, f64>) -> Result<Self> {
        let fail = |problem: ConfigProblem| config_error(path, problem);
        let mm_per_unit = check_hexapod_units(ini, hal).map_err(fail)?;
        let joint = |part: &str, leg: usize| -> Result<DVec3> {
            let mut xyz = [0.0; 3];
            for (value, axis) in xyz.iter_mut().zip(["x", "y", "z"]) {
                let name = format!("genhexkins.{part}.{leg}.{axis}");
                *value = *hal
                    .get(&name)
                    .ok_or_else(|| fail(ConfigProblem::MissingSetp { name: name.clone() }))?;
            }
            Ok(DVec3::from_array(xyz))
        };
        let mut base_joints = [DVec3::ZERO; LEGS];
        let mut platform_joints = [DVec3::ZERO; LEGS];
        for leg in 0..LEGS {
            base_joints[leg] = joint("base", leg)?;
            platform_joints[leg] = joint("platform", leg)?;
        }
        let home = parse_numbers::<6>(ini.first("TRAJ", "HOME").unwrap_or("0 0 0 0 0 0")).map_err(
            |problem| {
                fail(ConfigProblem::Numbers {
                    at: "[TRAJ]HOME".into(),
                    problem,
                })
            },
        )?;
        let joint_limits = common_travel(ini).map_err(fail)?;
        let machine = ini
            .first("EMC", "MACHINE")
            .map(str::to_string)
            .unwrap_or_else(|| {
                path.file_stem()
                    .unwrap_or_default()
                    .to_string_lossy()
                    .into()
            });
        Ok(Self {
            machine,
            mm_per_unit,
            base_joints,
            platform_joints,
            home,
            joint_limits,
        })
    }

    /// The geometry in hexacomp's units (mm, degrees), validated.
    ///
    /// Measured targets `P_1..P_3` default to the midpoints of the platform joint pairs (0, 1),
    /// (2, 3), (4, 5); replace them in the TOML with the points your measuring device sees.
    pub fn to_geometry(&self, options: &ConversionOptions) -> Result<Geometry> {
        let mm = self.mm_per_unit;
        let to_mm = |points: &[DVec3; LEGS]| points.map(|p| p * mm);
        let platform_joints = to_mm(&self.platform_joints);
        let home = [
            self.home[0] * mm,
            self.home[1] * mm,
            self.home[2] * mm,
            self.home[3],
            self.home[4],
            self.home[5],
        ];
        let leg_range = options
            .leg_range
            .unwrap_or([self.joint_limits[0] * mm, self.joint_limits[1] * mm]);
        if leg_range[0].is_nan() || leg_range[0] <= 0.0 {
            return Err(Error::NoLegStroke {
                min_mm: leg_range[0],
                max_mm: leg_range[1],
            });
        }
        let targets: Vec<DVec3> = (0..3)
            .map(|t| (platform_joints[2 * t] + platform_joints[2 * t + 1]) / 2.0)
            .collect();
        let base_joints = to_mm(&self.base_joints);
        let geometry = Geometry {
            name: self.machine.clone(),
            workspace: options
                .workspace
                .unwrap_or_else(|| default_workspace(&base_joints, home)),
            base_joints,
            platform_joints,
            leg_range,
            leg_offsets: [0.0; LEGS],
            home,
            targets,
            fiducials: Vec::new(),
        };
        geometry.validate()?;
        Ok(geometry)
    }
}

/// The configuration's own HAL files the ini's `[HAL]HALFILE` entries name (relative to the
/// ini's directory; `LIB:` files and Tcl files are LinuxCNC's own and hold no hexapod geometry).
fn hal_files_of(ini_path: &Path, ini: &Ini) -> Vec<PathBuf> {
    let dir = ini_path.parent().unwrap_or(Path::new("."));
    ini.all("HAL", "HALFILE")
        .filter_map(|entry| {
            let file = entry.split_whitespace().next().unwrap_or_default();
            (!file.starts_with("LIB:") && file.ends_with(".hal")).then(|| dir.join(file))
        })
        .collect()
}

/// The HAL files of the LinuxCNC configuration `ini_path` (those its `[HAL]HALFILE` entries
/// name), so that a command writing beside them can refuse to replace one.
pub fn hal_files(ini_path: &Path) -> Result<Vec<PathBuf>> {
    Ok(hal_files_of(ini_path, &Ini::read(ini_path)?))
}

/// The largest distance a joint of an exported geometry may lie from the configuration's, mm:
/// farther, it is another machine's (an identification moves joints by millimetres at most).
pub const MAX_EXPORT_SHIFT_MM: f64 = 25.0;

/// The joint settings of the ini that a leg's zero offset moves (joint coordinates, machine
/// units).
const OFFSET_KEYS: [&str; 4] = ["HOME_OFFSET", "HOME", "MIN_LIMIT", "MAX_LIMIT"];

/// The HAL lines that put `geometry` (an identified one, mm; `source` names it) into the LinuxCNC
/// hexapod configuration `ini_path`: `setp genhexkins.base.N.x …` and `genhexkins.platform.N.…`
/// in the configuration's units, to replace its own. genhexkins has no leg zero offsets: an
/// offset `o_i` (real joint-to-joint length minus encoder length) moves the joint's
/// `HOME_OFFSET`, `HOME`, `MIN_LIMIT` and `MAX_LIMIT` by `o_i`, which the text lists as comments
/// with the new values for the ini. Refused when a joint lies more than
/// [`MAX_EXPORT_SHIFT_MM`] from the configuration's (another machine).
pub fn genhexkins_hal(ini_path: &Path, geometry: &Geometry, source: &str) -> Result<String> {
    let current = LinuxCncHexapod::read(ini_path)?;
    let ini = Ini::read(ini_path)?;
    let mm = current.mm_per_unit;
    let joints = [
        ("base", &geometry.base_joints, &current.base_joints),
        (
            "platform",
            &geometry.platform_joints,
            &current.platform_joints,
        ),
    ];
    for (part, new, old) in &joints {
        for leg in 0..LEGS {
            let shift = (new[leg] - old[leg] * mm).length();
            if shift > MAX_EXPORT_SHIFT_MM {
                return Err(config_error(
                    ini_path,
                    ConfigProblem::AnotherMachine {
                        source: source.to_string(),
                        joint: format!("{part} joint {leg}"),
                        shift_mm: shift,
                    },
                ));
            }
        }
    }
    let unit = if mm == 1.0 {
        "mm".to_string()
    } else {
        format!("machine units of {mm} mm")
    };
    let mut text = format!(
        "# genhexkins geometry of {} from {source} (hexacomp-trainer export --linuxcnc), in {unit}:\n\
         # base joints B_i in the base frame, platform joints A_i in the platform frame. Replace the\n\
         # genhexkins setp lines of the configuration's HAL file with these.\n",
        current.machine
    );
    for (part, new, _) in &joints {
        for (leg, point) in new.iter().enumerate() {
            for (axis, value) in ["x", "y", "z"].iter().zip(point.to_array()) {
                text += &format!("setp genhexkins.{part}.{leg}.{axis} {}\n", value / mm);
            }
        }
    }
    if geometry.leg_offsets.iter().all(|o| *o == 0.0) {
        text += "# No leg zero offsets: the joints' settings in the ini stay as they are.\n";
        return Ok(text);
    }
    text += "# Leg zero offsets (real joint-to-joint length minus encoder length) are no genhexkins\n\
             # parameter: set the joints' positions in the ini to these values (each moved by the\n\
             # leg's offset), so that the joints hold real lengths:\n";
    for (leg, offset) in geometry.leg_offsets.iter().enumerate() {
        let section = format!("JOINT_{leg}");
        let moved: Vec<String> = OFFSET_KEYS
            .iter()
            .filter_map(|key| {
                let value = ini.first(&section, key)?;
                let [old] = parse_numbers::<1>(value).ok()?;
                Some(format!("{key} = {}", old + offset / mm))
            })
            .collect();
        text += &format!(
            "#   [{section}] offset {} {unit}: {}\n",
            offset / mm,
            if moved.is_empty() {
                "no HOME_OFFSET, HOME, MIN_LIMIT or MAX_LIMIT in the ini".to_string()
            } else {
                moved.join(", ")
            }
        );
    }
    Ok(text)
}

/// The workspace assumed when none is given: a cylinder of radius a tenth of the mean base joint
/// radius about the home position, as high as it is wide, tilt up to 10°, yaw ±10° (mm, degrees).
pub fn default_workspace(base_joints: &[DVec3; LEGS], home: [f64; 6]) -> Workspace {
    let mean_radius = base_joints
        .iter()
        .map(|b| b.truncate().length())
        .sum::<f64>()
        / LEGS as f64;
    let radius = 0.1 * mean_radius;
    Workspace {
        radius,
        z_range: [home[2] - radius, home[2] + radius],
        tilt_max: 10.0,
        yaw_range: [home[5] - 10.0, home[5] + 10.0],
    }
}

/// Refuses what is not a genhexkins hexapod in degrees with X Y Z A B C coordinates and no
/// screw lead; the millimetres per linear unit of `[TRAJ]LINEAR_UNITS`.
fn check_hexapod_units(
    ini: &Ini,
    hal: &BTreeMap<String, f64>,
) -> std::result::Result<f64, ConfigProblem> {
    let mm_per_unit = linear_units(ini.first("TRAJ", "LINEAR_UNITS").unwrap_or("mm"))?;
    match ini.first("TRAJ", "ANGULAR_UNITS").unwrap_or("degree") {
        "degree" | "deg" | "degrees" => {}
        other => {
            return Err(ConfigProblem::AngularUnits {
                value: other.to_string(),
            });
        }
    }
    let coordinates: String = ini
        .first("TRAJ", "COORDINATES")
        .unwrap_or("XYZABC")
        .split_whitespace()
        .collect();
    if !coordinates.eq_ignore_ascii_case("XYZABC") {
        return Err(ConfigProblem::Coordinates { value: coordinates });
    }
    if let Some(kinematics) = ini.first("KINS", "KINEMATICS")
        && !kinematics.starts_with("genhexkins")
    {
        return Err(ConfigProblem::Kinematics {
            value: kinematics.to_string(),
        });
    }
    if hal
        .get("genhexkins.screw-lead")
        .is_some_and(|&lead| lead != 0.0)
    {
        return Err(ConfigProblem::ScrewLead);
    }
    Ok(mm_per_unit)
}

/// The travel every leg allows, `[min, max]` in the configuration's units: the largest
/// `[JOINT_n]MIN_LIMIT` and the smallest `MAX_LIMIT`.
fn common_travel(ini: &Ini) -> std::result::Result<[f64; 2], ConfigProblem> {
    let limit = |leg: usize, key: &str| -> std::result::Result<f64, ConfigProblem> {
        let section = format!("JOINT_{leg}");
        let text = ini
            .first(&section, key)
            .ok_or_else(|| ConfigProblem::MissingTravel {
                entry: format!("[{section}]{key}"),
            })?;
        let [value] = parse_numbers::<1>(text).map_err(|problem| ConfigProblem::Numbers {
            at: format!("[{section}]{key}"),
            problem,
        })?;
        Ok(value)
    };
    let mut joint_limits = [f64::NEG_INFINITY, f64::INFINITY];
    for leg in 0..LEGS {
        joint_limits[0] = joint_limits[0].max(limit(leg, "MIN_LIMIT")?);
        joint_limits[1] = joint_limits[1].min(limit(leg, "MAX_LIMIT")?);
    }
    Ok(joint_limits)
}

/// Millimetres per unit of a `[TRAJ]LINEAR_UNITS` value (a name, or units per mm as a number).
fn linear_units(text: &str) -> std::result::Result<f64, ConfigProblem> {
    match text.to_ascii_lowercase().as_str() {
        "mm" | "metric" => Ok(1.0),
        "in" | "inch" | "imperial" => Ok(25.4),
        number => match number.parse::<f64>() {
            Ok(units_per_mm) if units_per_mm.is_finite() && units_per_mm > 0.0 => {
                Ok(1.0 / units_per_mm)
            }
            _ => Err(ConfigProblem::LinearUnits {
                value: text.to_string(),
            }),
        },
    }
}

/// `N` whitespace-separated finite numbers.
fn parse_numbers<const N: usize>(text: &str) -> std::result::Result<[f64; N], NumbersProblem> {
    let values: Vec<f64> = text
        .split_whitespace()
        .map(|word| {
            word.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| NumbersProblem::NotFinite {
                    word: word.to_string(),
                })
        })
        .collect::<std::result::Result<_, _>>()?;
    values
        .try_into()
        .map_err(|v: Vec<f64>| NumbersProblem::Count {
            got: v.len(),
            expected: N,
        })
}

/// Collects the numeric `setp NAME VALUE` and `NAME = VALUE` lines of a HAL file; `[SECTION]KEY`
/// values are looked up in the ini as halcmd does.
fn collect_setp(
    text: &str,
    ini: &Ini,
    parameters: &mut BTreeMap<String, f64>,
) -> std::result::Result<(), ConfigProblem> {
    for (number, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or_default();
        let words: Vec<&str> = line.split_whitespace().collect();
        let (name, value) = match words.as_slice() {
            ["setp", name, value] | [name, "=", value] => (*name, *value),
            _ => continue,
        };
        if !name.starts_with("genhexkins.") {
            continue;
        }
        let value = match value.strip_prefix('[').and_then(|v| v.split_once(']')) {
            Some((section, key)) => {
                ini.first(section, key)
                    .ok_or_else(|| ConfigProblem::IniReference {
                        line: number + 1,
                        entry: format!("[{section}]{key}"),
                    })?
            }
            None => value,
        };
        let [value] = parse_numbers::<1>(value).map_err(|problem| ConfigProblem::Numbers {
            at: format!("line {}", number + 1),
            problem,
        })?;
        parameters.insert(name.to_string(), value);
    }
    Ok(())
}

/// A LinuxCNC ini file: sections of `KEY = VALUE` lines, keys may repeat, `#` and `;` comments.
struct Ini {
    entries: Vec<(String, String, String)>,
}

impl Ini {
    fn read(path: &Path) -> Result<Self> {
        let text = read_text(path)?;
        let mut section = String::new();
        let mut entries = Vec::new();
        for line in text.lines() {
            let line = line.trim();
            if line.starts_with('#') || line.starts_with(';') || line.is_empty() {
                continue;
            }
            if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
                section = name.trim().to_string();
            } else if let Some((key, value)) = line.split_once('=') {
                entries.push((section.clone(), key.trim().into(), value.trim().into()));
            }
        }
        Ok(Self { entries })
    }

    fn all<'a>(&'a self, section: &str, key: &str) -> impl Iterator<Item = &'a str> + use<'a> {
        let (section, key) = (section.to_string(), key.to_string());
        self.entries
            .iter()
            .filter(move |(s, k, _)| *s == section && *k == key)
            .map(|(_, _, v)| v.as_str())
    }

    fn first(&self, section: &str, key: &str) -> Option<&str> {
        self.all(section, key).next()
    }
}

fn read_text(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|e| {
        config_error(
            path,
            ConfigProblem::Unreadable {
                cause: e.to_string(),
            },
        )
    })
}

fn config_error(path: &Path, problem: ConfigProblem) -> Error {
    Error::LinuxCncConfig {
        path: PathBuf::from(path),
        problem,
    }
}

/// What is wrong with a LinuxCNC configuration's ini or HAL file.
#[derive(Debug, Clone, PartialEq)]
pub enum ConfigProblem {
    /// The file cannot be read.
    Unreadable {
        /// Why.
        cause: String,
    },
    /// `[TRAJ]LINEAR_UNITS` is not mm, inch or a number.
    LinearUnits {
        /// Its value.
        value: String,
    },
    /// `[TRAJ]ANGULAR_UNITS` is not degrees.
    AngularUnits {
        /// Its value.
        value: String,
    },
    /// `[TRAJ]COORDINATES` is not X Y Z A B C.
    Coordinates {
        /// Its value.
        value: String,
    },
    /// `[KINS]KINEMATICS` is not genhexkins.
    Kinematics {
        /// Its value.
        value: String,
    },
    /// `genhexkins.screw-lead` is not 0: leg lengths then depend on the leg rotation.
    ScrewLead,
    /// A genhexkins joint coordinate is not set in the HAL files.
    MissingSetp {
        /// The parameter (`genhexkins.base.0.x`).
        name: String,
    },
    /// A joint's travel limit is missing.
    MissingTravel {
        /// The entry (`[JOINT_0]MIN_LIMIT`).
        entry: String,
    },
    /// A HAL line refers to an ini entry that is not there.
    IniReference {
        /// The HAL file's line, from 1.
        line: usize,
        /// The entry referred to.
        entry: String,
    },
    /// An entry's numbers are not what it needs.
    Numbers {
        /// Where (`[TRAJ]HOME`, `line 12`).
        at: String,
        /// What is wrong.
        problem: NumbersProblem,
    },
    /// An export's geometry is another machine's than the configuration's.
    AnotherMachine {
        /// The geometry's source.
        source: String,
        /// The joint that lies far ("base joint 0").
        joint: String,
        /// How far, mm.
        shift_mm: f64,
    },
}

/// What is wrong with a list of numbers.
#[derive(Debug, Clone, PartialEq)]
pub enum NumbersProblem {
    /// A word that is not a finite number.
    NotFinite {
        /// The word.
        word: String,
    },
    /// Another count of numbers than belong.
    Count {
        /// The numbers given.
        got: usize,
        /// The numbers that belong.
        expected: usize,
    },
}

impl std::fmt::Display for NumbersProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NotFinite { word } => write!(f, "`{word}` is not a finite number"),
            Self::Count { got, expected } => write!(f, "{got} numbers where {expected} belong"),
        }
    }
}

impl std::fmt::Display for ConfigProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Unreadable { cause } => f.write_str(cause),
            Self::LinearUnits { value } => {
                write!(f, "[TRAJ]LINEAR_UNITS = {value}: not mm, inch or a number")
            }
            Self::AngularUnits { value } => {
                write!(f, "[TRAJ]ANGULAR_UNITS = {value}: only degrees")
            }
            Self::Coordinates { value } => {
                write!(
                    f,
                    "[TRAJ]COORDINATES = {value}: a hexapod needs X Y Z A B C"
                )
            }
            Self::Kinematics { value } => write!(
                f,
                "[KINS]KINEMATICS = {value}: only genhexkins configurations are hexapods"
            ),
            Self::ScrewLead => f.write_str(
                "genhexkins.screw-lead is not 0: leg lengths then depend on the leg rotation, \
                 which hexacomp's kinematics do not model",
            ),
            Self::MissingSetp { name } => {
                write!(f, "no `setp {name}` in the HAL files the ini names")
            }
            Self::MissingTravel { entry } => write!(f, "no {entry}: the leg travel is needed"),
            Self::IniReference { line, entry } => {
                write!(f, "line {line}: {entry} is not in the ini")
            }
            Self::Numbers { at, problem } => write!(f, "{at}: {problem}"),
            Self::AnotherMachine {
                source,
                joint,
                shift_mm,
            } => write!(
                f,
                "{source}: its {joint} lies {shift_mm:.1} mm from this configuration's: it is \
                 another machine's geometry"
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example_ini() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../integrations/linuxcnc/hexapod-sim/hexapod-hexacomp.ini")
    }

    /// A copy of the example configuration with `edit` applied to the file `name`.
    fn edited(name: &str, edit: impl FnOnce(String) -> String) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        let example = example_ini().parent().unwrap().to_path_buf();
        let mut edit = Some(edit);
        for file in ["hexapod-hexacomp.ini", "kinematics.hal", "hexacomp.hal"] {
            let text = std::fs::read_to_string(example.join(file)).unwrap();
            let text = match (file == name, edit.take_if(|_| file == name)) {
                (true, Some(edit)) => edit(text),
                _ => text,
            };
            std::fs::write(dir.path().join(file), text).unwrap();
        }
        dir
    }

    fn read_edited(name: &str, edit: impl FnOnce(String) -> String) -> Result<LinuxCncHexapod> {
        let dir = edited(name, edit);
        LinuxCncHexapod::read(&dir.path().join("hexapod-hexacomp.ini"))
    }

    /// The example's geometry with its joints moved by up to a millimetre and leg offsets, as an
    /// identification gives.
    fn identified_example() -> Geometry {
        let mut g = LinuxCncHexapod::read(&example_ini())
            .unwrap()
            .to_geometry(&ConversionOptions::default())
            .unwrap();
        for leg in 0..LEGS {
            let k = leg as f64;
            g.base_joints[leg] += DVec3::new(0.3 * k - 0.7, -0.2 + 0.11 * k, 0.05 * k);
            g.platform_joints[leg] += DVec3::new(-0.1 * k, 0.4 - 0.13 * k, 0.2);
        }
        g.leg_offsets = [0.5, -0.25, 0.125, 0.0, 0.0625, -1.0];
        g
    }

    #[test]
    fn an_exported_geometry_reads_back_exactly_and_lists_the_joints_moved_by_the_offsets() {
        let identified = identified_example();
        let text = genhexkins_hal(&example_ini(), &identified, "identified.toml").unwrap();
        let dir = edited("kinematics.hal", |_| text.clone());
        let back = LinuxCncHexapod::read(&dir.path().join("hexapod-hexacomp.ini"))
            .unwrap()
            .to_geometry(&ConversionOptions::default())
            .unwrap();
        for leg in 0..LEGS {
            assert!((back.base_joints[leg] - identified.base_joints[leg]).length() < 1e-9);
            assert!((back.platform_joints[leg] - identified.platform_joints[leg]).length() < 1e-9);
        }
        // Leg 0: offset 0.5 mm = 0.5/25.4 in on the example's 29.7466 in home offset.
        let moved = format!("HOME_OFFSET = {}", 29.7466 + 0.5 / 25.4);
        let line = text.lines().find(|l| l.contains("[JOINT_0]")).unwrap();
        assert!(
            line.contains(&moved) && line.contains("MAX_LIMIT = "),
            "{line}"
        );
        // Another machine's geometry is refused.
        let error = genhexkins_hal(&example_ini(), &Geometry::prototype(), "p.toml").unwrap_err();
        assert!(
            error.to_string().contains("another machine's geometry"),
            "{error}"
        );
    }

    #[test]
    fn the_example_configuration_converts_to_mm() {
        let hexapod = LinuxCncHexapod::read(&example_ini()).unwrap();
        assert_eq!(hexapod.mm_per_unit, 25.4);
        assert_eq!(hexapod.joint_limits, [25.0, 35.0]);
        let geometry = hexapod.to_geometry(&ConversionOptions::default()).unwrap();
        assert_eq!(geometry.name, "hexapod-sim-hexacomp");
        assert_eq!(
            geometry.base_joints[0],
            DVec3::new(-22.95 * 25.4, 13.25 * 25.4, 0.0)
        );
        assert_eq!(
            geometry.platform_joints[3],
            DVec3::new(9.459 * 25.4, -6.616 * 25.4, 0.0)
        );
        assert_eq!(geometry.leg_range, [635.0, 889.0]);
        assert_eq!(geometry.home, [0.0, 0.0, 508.0, 0.0, 0.0, 0.0]);
        // The ini's joint HOME (29.7466 in, rounded by LinuxCNC's authors) is the home pose's leg.
        let legs = hexacomp_core::inverse_kinematics(&geometry, &geometry.home_pose()).lengths;
        for leg in legs {
            assert!((leg / 25.4 - 29.7466).abs() < 1e-3, "{leg}");
        }
        let w = geometry.workspace;
        // A tenth of the base joints' radius (26.5 in to 0.02 %).
        assert!((w.radius - 0.1 * 26.5 * 25.4).abs() < 0.01, "{w:?}");
        assert_eq!(w.z_range, [508.0 - w.radius, 508.0 + w.radius]);
    }

    #[test]
    fn ini_values_named_in_hal_files_are_looked_up() {
        let dir = edited("kinematics.hal", |hal| {
            hal.replace(
                "setp genhexkins.base.0.x -22.950",
                "setp genhexkins.base.0.x [HEXAPOD]B0X",
            )
        });
        let ini = dir.path().join("hexapod-hexacomp.ini");
        let text = std::fs::read_to_string(&ini).unwrap() + "\n[HEXAPOD]\nB0X = -23.5\n";
        std::fs::write(&ini, text).unwrap();
        let hexapod = LinuxCncHexapod::read(&ini).unwrap();
        assert_eq!(hexapod.base_joints[0].x, -23.5);
    }

    #[test]
    fn metric_and_numeric_units() {
        let mm = read_edited("hexapod-hexacomp.ini", |t| {
            t.replace("LINEAR_UNITS = inch", "LINEAR_UNITS = mm")
        })
        .unwrap();
        assert_eq!(mm.mm_per_unit, 1.0);
        let numeric = read_edited("hexapod-hexacomp.ini", |t| {
            t.replace("LINEAR_UNITS = inch", "LINEAR_UNITS = 0.1")
        })
        .unwrap();
        assert_eq!(numeric.mm_per_unit, 10.0);
    }

    #[test]
    fn what_cannot_be_converted_is_named() {
        type Edit = fn(String) -> String;
        let cases: [(&str, Edit, &str); 5] = [
            (
                "kinematics.hal",
                |t| t.replace("setp genhexkins.platform.4.y  -6.616\n", ""),
                "genhexkins.platform.4.y",
            ),
            (
                "hexapod-hexacomp.ini",
                |t| t.replace("LINEAR_UNITS = inch", "LINEAR_UNITS = furlong"),
                "furlong",
            ),
            (
                "hexapod-hexacomp.ini",
                |t| t.replace("KINEMATICS = genhexkins", "KINEMATICS = trivkins"),
                "trivkins",
            ),
            (
                "kinematics.hal",
                |t| t + "setp genhexkins.screw-lead 0.2\n",
                "screw-lead",
            ),
            (
                "hexapod-hexacomp.ini",
                |t| t.replacen("HOME = 0 0 20 0 0 0", "HOME = 0 0 20 0 0", 1),
                "[TRAJ]HOME",
            ),
        ];
        for (file, edit, expected) in cases {
            let message = read_edited(file, edit).unwrap_err().to_string();
            assert!(message.contains(expected), "{message}");
        }
    }

    #[test]
    fn joint_limits_that_are_no_stroke_need_an_explicit_one() {
        let hexapod = read_edited("hexapod-hexacomp.ini", |t| {
            t.replace("MIN_LIMIT = 25.0", "MIN_LIMIT = -1000.0")
        })
        .unwrap();
        let message = hexapod
            .to_geometry(&ConversionOptions::default())
            .unwrap_err()
            .to_string();
        assert!(message.contains("--leg-range"), "{message}");
        let options = ConversionOptions {
            leg_range: Some([640.0, 880.0]),
            workspace: None,
        };
        assert_eq!(
            hexapod.to_geometry(&options).unwrap().leg_range,
            [640.0, 880.0]
        );
    }
}
