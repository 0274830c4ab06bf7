//! What `verify` writes: the raw attained poses (CSV), the report (JSON, the contract other tools
//! read; docs/formats.md) and a readable HTML page with a chart of the attained points around each
//! commanded pose, before and after side by side when a previous run is given.

use std::fmt::Write;

use crate::error::{Error, Result};
use crate::pose_test::{PoseCharacteristics, TestCube, TestPose};
use crate::verify::{Attained, Missed};
use hexacomp_report::chart::{Axis, Chart, Series};

/// The conditions of a test, as ISO 9283 asks them reported.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Conditions {
    /// The machine and the instrument.
    pub rig: String,
    /// The instrument's maximum permissible error `A + B·L` as `[A µm, B µm/m]`, when stated.
    pub instrument_mpe_um: Option<[f64; 2]>,
    /// Readings combined per attained pose.
    pub readings: usize,
    /// Seconds between two readings.
    pub dwell_s: f64,
    /// Cycles run.
    pub cycles: usize,
    /// Air temperature during the test, °C, when given.
    pub air_temperature_c: Option<f64>,
    /// Machine temperature during the test, °C, when given.
    pub machine_temperature_c: Option<f64>,
    /// The model the virtual machine applied (`--model`), if any.
    pub model: Option<String>,
    /// The registration that brought the measurements into the base frame, if any.
    pub registration: Option<String>,
    /// The geometry's fingerprint.
    pub geometry: String,
}

/// One pose of the report: its name, commanded pose, figures and attained poses.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PoseReport {
    /// P1…P5, O1…O6, E1…
    pub name: String,
    /// The commanded pose `x, y, z, a, b, c`, mm and degrees, base frame.
    pub commanded: [f64; 6],
    /// AP and RP (ISO 9283 § 7.2).
    #[serde(flatten)]
    pub figures: PoseCharacteristics,
    /// The attained poses the figures come from, mm and degrees, in cycle order.
    pub attained: Vec<[f64; 6]>,
}

/// A pose not measured in a cycle.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct MissedReport {
    /// The cycle, from 1.
    pub cycle: usize,
    /// The pose's name.
    pub pose: String,
    /// Why it was not measured.
    pub why: String,
}

/// The report of one test (`verify --json`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VerifyReport {
    /// The standard and the characteristics reported.
    pub standard: String,
    /// When the test ended (RFC 3339).
    pub created: String,
    /// The test conditions.
    pub conditions: Conditions,
    /// The test cube: centre (mm, base frame) and side (mm).
    pub cube_centre_mm: [f64; 3],
    /// The test cube's side, mm.
    pub cube_side_mm: f64,
    /// Every pose, in the order of a cycle.
    pub poses: Vec<PoseReport>,
    /// Poses not measured in some cycle (left out of that pose's figures).
    pub missed: Vec<MissedReport>,
}

/// The text the report's `standard` holds.
pub const STANDARD: &str = "ISO 9283:1998 pose accuracy (AP) and pose repeatability (RP)";

impl VerifyReport {
    /// The report of a test: `figures[k]` belongs to `poses[k]` (name, commanded).
    pub fn new(
        conditions: Conditions,
        cube: &TestCube,
        poses: &[(String, [f64; 6])],
        figures: &[PoseCharacteristics],
        attained: &[Attained],
        missed: &[Missed],
        created: String,
    ) -> Self {
        Self {
            standard: STANDARD.into(),
            created,
            conditions,
            cube_centre_mm: cube.centre.to_array(),
            cube_side_mm: cube.side_mm,
            poses: poses
                .iter()
                .zip(figures)
                .map(|((name, commanded), figures)| PoseReport {
                    name: name.clone(),
                    commanded: *commanded,
                    figures: *figures,
                    attained: attained
                        .iter()
                        .filter(|a| &a.pose == name)
                        .map(|a| a.pose_mm_deg)
                        .collect(),
                })
                .collect(),
            missed: missed
                .iter()
                .map(|m| MissedReport {
                    cycle: m.cycle,
                    pose: m.pose.clone(),
                    why: m.why.clone(),
                })
                .collect(),
        }
    }

    /// The report as JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a report serialises") + "\n"
    }

    /// Reads a report written by `verify --json`; `file` names it in errors.
    pub fn from_json(text: &str, file: &str) -> Result<Self> {
        let report: Self = serde_json::from_str(text).map_err(|e| Error::NotAReport {
            file: file.to_string(),
            cause: e.to_string(),
        })?;
        if report.standard != STANDARD {
            return Err(Error::OtherStandard {
                file: file.to_string(),
                standard: report.standard,
                expected: STANDARD,
            });
        }
        Ok(report)
    }

    /// Refuses this report (read from `file`) as the run before a test of `poses` unless it
    /// tested the same poses (names, and commanded poses to 1e-6 mm and degrees), so that the two
    /// can be set side by side; checked before the test moves anything.
    pub fn check_same_poses(&self, poses: &[TestPose], file: &str) -> Result<()> {
        let same = self.poses.len() == poses.len()
            && poses.iter().zip(&self.poses).all(|(a, b)| {
                a.name == b.name
                    && a.commanded
                        .iter()
                        .zip(&b.commanded)
                        .all(|(x, y)| (x - y).abs() <= 1e-6)
            });
        if same {
            Ok(())
        } else {
            Err(Error::OtherPoses {
                file: file.to_string(),
                reported: names(&self.poses),
                run: poses
                    .iter()
                    .map(|p| p.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
            })
        }
    }

    /// The largest AP_P over the poses, mm.
    pub fn worst_ap_p_mm(&self) -> f64 {
        self.poses
            .iter()
            .map(|p| p.figures.ap_p_mm)
            .fold(0.0, f64::max)
    }

    /// The largest RP_l over the poses, mm.
    pub fn worst_rp_l_mm(&self) -> f64 {
        self.poses
            .iter()
            .map(|p| p.figures.rp_l_mm)
            .fold(0.0, f64::max)
    }
}

/// The poses' names, comma-separated.
fn names(poses: &[PoseReport]) -> String {
    poses
        .iter()
        .map(|p| p.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

/// The raw attained poses as CSV: `cycle,pose,x,y,z,a,b,c` (mm, degrees, base frame), every
/// number written to the bit.
pub fn raw_csv(attained: &[Attained]) -> String {
    let mut text = String::from("cycle,pose,x,y,z,a,b,c\n");
    for a in attained {
        let _ = write!(text, "{},{}", a.cycle, a.pose);
        for value in a.pose_mm_deg {
            let _ = write!(text, ",{value:?}");
        }
        text.push('\n');
    }
    text
}

/// The chart of one pose's attained positions around the commanded one: `x–y` and `x–z`
/// deviations in µm, and their barycentre.
fn pose_chart(pose: &PoseReport, run: &str) -> Result<String> {
    let deviation = |p: &[f64; 6], k: usize| (p[k] - pose.commanded[k]) * 1000.0;
    let scatter = |label: &str, points: Vec<(f64, f64)>| Series {
        label: label.into(),
        points,
        error_bars: None,
        markers_only: true,
    };
    let centre = &pose.figures.barycentre;
    Chart {
        title: format!(
            "{} {run}: AP_P {:.1} µm, RP_l {:.1} µm",
            pose.name,
            pose.figures.ap_p_mm * 1000.0,
            pose.figures.rp_l_mm * 1000.0
        ),
        x: Axis::linear("Δx, µm"),
        y: Axis::linear("Δy or Δz, µm"),
        series: vec![
            scatter(
                "attained (Δx, Δy)",
                pose.attained
                    .iter()
                    .map(|p| (deviation(p, 0), deviation(p, 1)))
                    .collect(),
            ),
            scatter(
                "attained (Δx, Δz)",
                pose.attained
                    .iter()
                    .map(|p| (deviation(p, 0), deviation(p, 2)))
                    .collect(),
            ),
            scatter(
                "barycentre",
                vec![
                    (deviation(centre, 0), deviation(centre, 1)),
                    (deviation(centre, 0), deviation(centre, 2)),
                ],
            ),
            scatter("commanded", vec![(0.0, 0.0)]),
        ],
    }
    .to_svg()
    .map_err(Error::from)
}

/// How `after` compares with `before` (both errors, mm): "12.3× better", "1.4× worse" or "the
/// same".
pub fn improvement(before: f64, after: f64) -> String {
    if before > after {
        if after > 0.0 {
            format!("{:.1}× better", before / after)
        } else {
            "better: no error left".into()
        }
    } else if after > before {
        if before > 0.0 {
            format!("{:.1}× worse", after / before)
        } else {
            "worse".into()
        }
    } else {
        "the same".into()
    }
}

/// Escapes text for HTML.
fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A figure in µm with one decimal.
fn um(mm: f64) -> String {
    format!("{:.1}", mm * 1000.0)
}

/// A figure in degrees with four decimals.
fn deg(value: f64) -> String {
    format!("{value:.4}")
}

/// The readable report of `after`, with `before` beside it when given.
///
/// # Errors
/// [`Error::Report`] when a pose's chart cannot be drawn.
pub fn html(after: &VerifyReport, before: Option<&VerifyReport>) -> Result<String> {
    let mut page = String::new();
    let _ = write!(
        page,
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>ISO 9283 pose test</title>\n\
         <style>body{{font-family:sans-serif;margin:2em}}table{{border-collapse:collapse}}\
         td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right}}\
         td:first-child{{text-align:left}}svg{{width:560px;height:auto}}</style></head><body>\n\
         <h1>ISO 9283 pose test</h1>\n<p>{}. Poses P1–P5 on the diagonal plane of the test cube \
         (centre {:?} mm, side {:.1} mm); O1–O6 orientation poses about P1; E… extra poses. \
         AP_P and RP_l in µm, angles in degrees.</p>\n",
        escape(STANDARD),
        after.cube_centre_mm,
        after.cube_side_mm
    );
    for (label, report) in before
        .into_iter()
        .map(|r| ("Before", r))
        .chain([(if before.is_some() { "After" } else { "Run" }, after)])
    {
        run_section(&mut page, label, report);
    }
    if let Some(before) = before {
        let _ = writeln!(
            page,
            "<p>Worst AP_P: {} µm before, {} µm after ({}); worst RP_l: {} µm before, {} µm \
             after.</p>",
            um(before.worst_ap_p_mm()),
            um(after.worst_ap_p_mm()),
            improvement(before.worst_ap_p_mm(), after.worst_ap_p_mm()),
            um(before.worst_rp_l_mm()),
            um(after.worst_rp_l_mm())
        );
    }
    pose_charts(&mut page, after, before)?;
    page.push_str("</body></html>\n");
    Ok(page)
}

/// One run's section of the page: its conditions, its table of characteristics and the
/// readings it missed.
fn run_section(page: &mut String, label: &str, report: &VerifyReport) {
    let c = &report.conditions;
    let _ = writeln!(
        page,
        "<h2>{label}</h2>\n<p>{}; {} cycles, {} readings per pose, {} s dwell; model: {}; \
         registration: {}; air {} °C, machine {} °C; instrument MPE {}; ended {}.</p>",
        escape(&c.rig),
        c.cycles,
        c.readings,
        c.dwell_s,
        escape(c.model.as_deref().unwrap_or("none")),
        escape(c.registration.as_deref().unwrap_or("none")),
        c.air_temperature_c.map_or("–".into(), |t| t.to_string()),
        c.machine_temperature_c
            .map_or("–".into(), |t| t.to_string()),
        c.instrument_mpe_um
            .map_or("not stated".into(), |[a, b]| format!("{a} µm + {b} µm/m")),
        escape(&report.created)
    );
    page.push_str(
        "<table><tr><th>pose</th><th>n</th><th>AP_P</th><th>AP_a</th><th>AP_b</th>\
         <th>AP_c</th><th>RP_l</th><th>RP_a</th><th>RP_b</th><th>RP_c</th></tr>\n",
    );
    for pose in &report.poses {
        let f = &pose.figures;
        let _ = writeln!(
            page,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>\
             <td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(&pose.name),
            f.cycles,
            um(f.ap_p_mm),
            deg(f.ap_a_deg),
            deg(f.ap_b_deg),
            deg(f.ap_c_deg),
            um(f.rp_l_mm),
            deg(f.rp_a_deg),
            deg(f.rp_b_deg),
            deg(f.rp_c_deg)
        );
    }
    page.push_str("</table>\n");
    if !report.missed.is_empty() {
        page.push_str("<p>Not measured (left out of their pose's figures):</p><ul>\n");
        for m in &report.missed {
            let _ = writeln!(
                page,
                "<li>{} in cycle {}: {}</li>",
                escape(&m.pose),
                m.cycle,
                escape(&m.why)
            );
        }
        page.push_str("</ul>\n");
    }
}

/// The table of each pose's chart of attained points, before and after side by side.
fn pose_charts(
    page: &mut String,
    after: &VerifyReport,
    before: Option<&VerifyReport>,
) -> Result<()> {
    page.push_str("<h2>Attained points around each commanded pose</h2>\n<table>\n");
    for (k, pose) in after.poses.iter().enumerate() {
        page.push_str("<tr>");
        if let Some(before) = before {
            let _ = write!(page, "<td>{}</td>", pose_chart(&before.poses[k], "before")?);
        }
        let _ = write!(
            page,
            "<td>{}</td>",
            pose_chart(pose, if before.is_some() { "after" } else { "" })?
        );
        page.push_str("</tr>\n");
    }
    page.push_str("</table>\n");
    Ok(())
}
