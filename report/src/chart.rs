//! Line and scatter charts for the reports, drawn as SVG by `plotters` (its SVG backend alone:
//! no bitmap code and no font files; the text is left to the viewer's sans-serif font).
//!
//! An axis is linear, logarithmic, or a percentile axis: the quantile `p` drawn at
//! `log₁₀ 1/(1−p)` and labelled in per cent, the usual scale of latency distributions, on which
//! 90 %, 99 % and 99.9 % are equally spaced.

use plotters::coord::Shift;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;

use crate::error::Error;

/// One series of a chart.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Points `(x, y)`, in the units of the chart's axes.
    pub points: Vec<(f64, f64)>,
    /// Optional half-height of an error bar per point (same length as `points`, y units).
    pub error_bars: Option<Vec<f64>>,
    /// Draw markers only, no connecting line.
    pub markers_only: bool,
}

impl Series {
    /// A line series.
    pub fn line(label: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Self {
            label: label.into(),
            points,
            error_bars: None,
            markers_only: false,
        }
    }
}

/// How an axis places its values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Linear; a linear y axis always includes 0.
    Linear,
    /// Base-10 logarithmic, over whole decades; values ≤ 0 cannot be drawn and are left out.
    Log,
    /// Quantiles `p` in [0, 1), drawn at `log₁₀ 1/(1−p)` and labelled in per cent (0 %, 90 %,
    /// 99 %, …); values outside [0, 1) are left out.
    Percentile,
}

/// One axis of a chart: its label and its scale.
#[derive(Debug, Clone)]
pub struct Axis {
    /// The label, with the unit.
    pub label: String,
    /// How values are placed.
    pub scale: Scale,
}

impl Axis {
    /// A linear axis.
    pub fn linear(label: impl Into<String>) -> Self {
        Self {
            label: label.into(),
            scale: Scale::Linear,
        }
    }

    /// A base-10 logarithmic axis.
    pub fn log(label: impl Into<String>) -> Self {
        Self {
            label: label.into(),
            scale: Scale::Log,
        }
    }

    /// A percentile axis (values are quantiles in [0, 1)).
    pub fn percentile(label: impl Into<String>) -> Self {
        Self {
            label: label.into(),
            scale: Scale::Percentile,
        }
    }
}

/// A chart: title, axes and series.
#[derive(Debug, Clone)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// The horizontal axis.
    pub x: Axis,
    /// The vertical axis.
    pub y: Axis,
    /// The series, drawn in order and listed in the legend on the right.
    pub series: Vec<Series>,
}

const WIDTH: u32 = 800;
const HEIGHT: u32 = 480;
const LEGEND_WIDTH: u32 = 190;
const FONT: &str = "sans-serif";
const COLOURS: [RGBColor; 8] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xd6, 0x27, 0x28),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x94, 0x67, 0xbd),
    RGBColor(0x8c, 0x56, 0x4b),
    RGBColor(0xe3, 0x77, 0xc2),
    RGBColor(0x7f, 0x7f, 0x7f),
];
/// Series with at most this many points get a marker at each point.
const MARKED_UP_TO: usize = 60;

/// The largest magnitude an axis places (and the smallest positive value a log axis does):
/// beyond it the axis's range and ticks could not be computed.
const LARGEST: f64 = 1e300;

/// A series' points where the axes place them: `(x, y, (bar low, bar high))`, a bar's low end
/// `None` where the axis cannot place it (below zero on a log axis: drawn to the axis's bottom).
type Placed = Vec<(f64, f64, Option<(Option<f64>, f64)>)>;
type Drawn = Result<(), DrawingAreaErrorKind<std::io::Error>>;

impl Chart {
    /// The chart as an SVG document. Points an axis cannot place (not finite, beyond 1e300 in
    /// magnitude, ≤ 1e-300 on a log axis, outside [0, 1) on a percentile axis) are left out.
    pub fn to_svg(&self) -> Result<String, Error> {
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, (WIDTH, HEIGHT)).into_drawing_area();
            self.draw(&root)
                .and_then(|()| root.present())
                .map_err(|e| Error::Chart {
                    title: self.title.clone(),
                    message: e.to_string(),
                })?;
        }
        Ok(svg)
    }

    fn draw(&self, root: &DrawingArea<SVGBackend<'_>, Shift>) -> Drawn {
        root.fill(&WHITE)?;
        let placed: Vec<Placed> = self.series.iter().map(|s| self.place(s)).collect();
        let x_range = range(self.x.scale, placed.iter().flatten().map(|p| p.0), false);
        let y_range = range(
            self.y.scale,
            placed
                .iter()
                .flatten()
                .flat_map(|p| [Some(p.1), p.2.and_then(|b| b.0), p.2.map(|b| b.1)])
                .flatten(),
            true,
        );
        let bottom = y_range.start;
        let (plot, legend) = root.split_horizontally(WIDTH - LEGEND_WIDTH);
        let placed = (placed.as_slice(), bottom);
        match (self.x.scale, self.y.scale) {
            (Scale::Linear, Scale::Linear) => self.draw_in(&plot, x_range, y_range, placed),
            (Scale::Linear, _) => self.draw_in(&plot, x_range, y_range.log_scale(), placed),
            (_, Scale::Linear) => self.draw_in(&plot, x_range.log_scale(), y_range, placed),
            (_, _) => self.draw_in(&plot, x_range.log_scale(), y_range.log_scale(), placed),
        }?;
        self.draw_legend(&legend)
    }

    /// The points of `series` where the axes place them, without those they cannot place.
    fn place(&self, series: &Series) -> Placed {
        series
            .points
            .iter()
            .enumerate()
            .filter_map(|(i, &(x, value))| {
                let x = position(self.x.scale, x)?;
                let y = position(self.y.scale, value)?;
                let bar = series.error_bars.as_ref().and_then(|bars| {
                    let half = bars.get(i)?.abs();
                    half.is_finite().then(|| {
                        let low = position(self.y.scale, value - half);
                        (low, position(self.y.scale, value + half).unwrap_or(y))
                    })
                });
                Some((x, y, bar))
            })
            .collect()
    }

    fn draw_in<X, Y>(
        &self,
        area: &DrawingArea<SVGBackend<'_>, Shift>,
        x_range: X,
        y_range: Y,
        (placed, bottom): (&[Placed], f64),
    ) -> Drawn
    where
        X: AsRangedCoord<Value = f64>,
        Y: AsRangedCoord<Value = f64>,
        X::CoordDescType: ValueFormatter<f64>,
        Y::CoordDescType: ValueFormatter<f64>,
    {
        let mut chart = ChartBuilder::on(area)
            .caption(&self.title, (FONT, 16))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(64)
            .build_cartesian_2d(x_range, y_range)?;
        let x_labels = tick_label(self.x.scale);
        let y_labels = tick_label(self.y.scale);
        chart
            .configure_mesh()
            .x_desc(&self.x.label)
            .y_desc(&self.y.label)
            .label_style((FONT, 12))
            .x_label_formatter(&x_labels)
            .y_label_formatter(&y_labels)
            .draw()?;
        for (index, (series, points)) in self.series.iter().zip(placed).enumerate() {
            let colour = COLOURS[index % COLOURS.len()];
            if !series.markers_only {
                chart.draw_series(LineSeries::new(
                    points.iter().map(|p| (p.0, p.1)),
                    colour.stroke_width(2),
                ))?;
            }
            if series.markers_only || points.len() <= MARKED_UP_TO {
                chart.draw_series(
                    points
                        .iter()
                        .map(|p| Circle::new((p.0, p.1), 3, colour.filled())),
                )?;
            }
            chart.draw_series(points.iter().filter_map(|&(x, y, bar)| {
                let (low, high) = bar?;
                let low = low.unwrap_or(bottom);
                Some(ErrorBar::new_vertical(
                    x,
                    low,
                    y,
                    high,
                    colour.stroke_width(1),
                    8,
                ))
            }))?;
        }
        Ok(())
    }

    fn draw_legend(&self, area: &DrawingArea<SVGBackend<'_>, Shift>) -> Drawn {
        for (index, series) in self.series.iter().enumerate() {
            let colour = COLOURS[index % COLOURS.len()];
            let y = 50 + 20 * index as i32;
            area.draw(&PathElement::new(
                vec![(4, y), (26, y)],
                colour.stroke_width(3),
            ))?;
            area.draw(&Text::new(
                series.label.as_str(),
                (32, y - 7),
                (FONT, 12).into_font(),
            ))?;
        }
        Ok(())
    }
}

/// Where an axis of `scale` places `value`, if it can.
fn position(scale: Scale, value: f64) -> Option<f64> {
    match scale {
        Scale::Linear => (value.abs() <= LARGEST).then_some(value),
        Scale::Log => (1.0 / LARGEST..=LARGEST).contains(&value).then_some(value),
        Scale::Percentile => (0.0..1.0).contains(&value).then(|| 1.0 / (1.0 - value)),
    }
}

/// The range of an axis holding `positions`: rounded to tick steps on a linear axis (from 0 on a
/// y axis), to whole decades on a log or percentile one.
fn range(
    scale: Scale,
    positions: impl Iterator<Item = f64>,
    from_zero: bool,
) -> std::ops::Range<f64> {
    let (mut lo, mut hi) = positions.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if scale == Scale::Linear {
        if from_zero {
            (lo, hi) = (lo.min(0.0), hi.max(0.0));
        }
        return nice_range(lo, hi);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return 1.0..10.0;
    }
    let lo = 10f64.powf(lo.log10().floor());
    let hi = 10f64.powf(hi.log10().ceil()).max(lo * 10.0);
    // A hair wider: plotters finds its decade ticks by rounding logarithms, and 0.1 (whose
    // logarithm is a hair above −1 in floating point) would lose its label.
    lo * (1.0 - 1e-9)..hi * (1.0 + 1e-9)
}

/// A range covering `[lo, hi]`, widened to round tick steps.
fn nice_range(lo: f64, hi: f64) -> std::ops::Range<f64> {
    if !lo.is_finite() || !hi.is_finite() {
        return 0.0..1.0;
    }
    if hi - lo < 1e-12 {
        return lo - 0.5..hi + 0.5;
    }
    let raw = (hi - lo) / 6.0;
    let magnitude = 10f64.powf(raw.log10().floor());
    let step = magnitude
        * match raw / magnitude {
            f if f < 1.5 => 1.0,
            f if f < 3.5 => 2.0,
            f if f < 7.5 => 5.0,
            _ => 10.0,
        };
    (lo / step).floor() * step..(hi / step).ceil() * step
}

/// How an axis of `scale` labels its ticks: numbers with as many decimals as their magnitude
/// needs; percentiles with one decimal more than their nines need (99.99999 % stays that).
fn tick_label(scale: Scale) -> impl Fn(&f64) -> String {
    move |&value| match scale {
        Scale::Percentile => {
            let nines = value.log10().ceil().max(0.0) as usize;
            let decimals = nines.saturating_sub(2) + 1;
            format!("{}%", trimmed(100.0 * (1.0 - 1.0 / value), decimals))
        }
        Scale::Linear | Scale::Log => {
            let magnitude = value.abs().log10().floor();
            let decimals = if magnitude.is_finite() {
                (3.0 - magnitude).clamp(6.0, 320.0) as usize
            } else {
                0
            };
            trimmed(value, decimals)
        }
    }
}

/// `value` with at most `decimals` decimals and no trailing zeros.
fn trimmed(value: f64, decimals: usize) -> String {
    let text = format!("{value:.decimals$}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    if text == "-0" { "0" } else { text }.to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn texts(svg: &str) -> Vec<String> {
        svg.split("<text")
            .skip(1)
            .map(|t| {
                let start = t.find('>').unwrap() + 1;
                t[start..t.find("</text>").unwrap()].trim().to_string()
            })
            .collect()
    }

    /// The points of the series' lines in the plot (the mesh and the axes are drawn in black,
    /// the legend right of the plot).
    fn series_lines(svg: &str) -> Vec<Vec<(f64, f64)>> {
        svg.split("<polyline")
            .skip(1)
            .filter(|line| !line.contains("stroke=\"#000000\""))
            .map(|line| {
                let points = &line[line.find("points=\"").unwrap() + 8..];
                points[..points.find('"').unwrap()]
                    .split_whitespace()
                    .map(|p| {
                        let (x, y) = p.split_once(',').unwrap();
                        (x.parse().unwrap(), y.parse().unwrap())
                    })
                    .collect::<Vec<(f64, f64)>>()
            })
            .filter(|points| points.iter().all(|p| p.0 < f64::from(WIDTH - LEGEND_WIDTH)))
            .collect()
    }

    #[test]
    fn linear_ranges_are_round_and_start_from_zero_on_y() {
        assert_eq!(nice_range(0.013, 0.087), 0.01..0.09);
        assert_eq!(range(Scale::Linear, [0.3, 0.8].into_iter(), true), 0.0..0.8);
        let decades = |r: std::ops::Range<f64>| (r.start.log10().round(), r.end.log10().round());
        assert_eq!(
            decades(range(Scale::Log, [0.9, 1.6].into_iter(), true)),
            (-1.0, 1.0)
        );
        assert_eq!(
            decades(range(Scale::Log, [1.0, 1.0].into_iter(), true)),
            (0.0, 1.0)
        );
        assert_eq!(trimmed(0.05, 6), "0.05");
        assert_eq!(trimmed(-0.0000001, 6), "0");
    }

    #[test]
    fn chart_has_every_series_and_escapes_labels() {
        let chart = Chart {
            title: "RMSE <mm> & nodes".into(),
            x: Axis::linear("hidden nodes"),
            y: Axis::linear("RMSE (mm)"),
            series: vec![
                Series::line("training", vec![(1.0, 0.2), (2.0, 0.1)]),
                Series::line("validation", vec![(1.0, 0.25), (2.0, 0.15)]),
            ],
        };
        let svg = chart.to_svg().unwrap();
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert_eq!(series_lines(&svg).len(), 2);
        let texts = texts(&svg);
        for label in [
            "RMSE &lt;mm&gt; &amp; nodes",
            "training",
            "validation",
            "RMSE (mm)",
        ] {
            assert!(texts.iter().any(|t| t == label), "{label} in {texts:?}");
        }
    }

    #[test]
    fn extreme_values_are_left_out_and_ticks_keep_their_digits() {
        let chart = Chart {
            title: "tiny and huge".into(),
            x: Axis::percentile("percentile"),
            y: Axis::log("value"),
            series: vec![Series {
                label: "values".into(),
                points: vec![(0.0, 1e-7), (0.9, 1e-5), (0.99, 1e308), (0.9999999, 1e-6)],
                // The second point's bar reaches below zero: drawn to the axis's bottom.
                error_bars: Some(vec![0.0, 1.0, 0.0, 0.0]),
                markers_only: false,
            }],
        };
        let svg = chart.to_svg().unwrap();
        let texts = texts(&svg);
        for label in ["0.0000001", "0.00001", "90%", "99.99999%"] {
            assert!(texts.iter().any(|t| t == label), "{label} in {texts:?}");
        }
        assert_eq!(series_lines(&svg)[0].len(), 3, "1e308 left out");
        let huge = Chart {
            title: "huge".into(),
            x: Axis::linear("x"),
            y: Axis::linear("y"),
            series: vec![Series::line(
                "h",
                vec![(-1e308, 0.0), (1e308, 1.0), (0.0, 2.0)],
            )],
        };
        assert_eq!(series_lines(&huge.to_svg().unwrap())[0].len(), 1);
    }

    #[test]
    fn percentile_axis_places_quantiles_by_their_nines_and_labels_them() {
        // Latencies of 1, 10 and 100 µs at the 0th, 90th and 99th percentiles lie on a straight
        // line on a percentile × log chart: equal steps in both directions.
        let chart = Chart {
            title: "round trip".into(),
            x: Axis::percentile("percentile"),
            y: Axis::log("round trip (µs)"),
            series: vec![
                Series::line(
                    "hexacomp",
                    vec![
                        (0.0, 1.0),
                        (0.9, 10.0),
                        (0.99, 100.0),
                        (1.0, 1e3),
                        (0.5, -1.0),
                    ],
                ),
                Series::line("a decade lower", vec![(0.0, 0.1), (0.9, 1.0)]),
            ],
        };
        let svg = chart.to_svg().unwrap();
        let texts = texts(&svg);
        for label in ["0%", "90%", "99%", "1", "10", "100", "0.1"] {
            assert!(texts.iter().any(|t| t == label), "{label} in {texts:?}");
        }
        let lines = series_lines(&svg);
        let xy = &lines[0];
        // p = 1 and the negative latency cannot be placed: three points, evenly spaced.
        assert_eq!(xy.len(), 3, "{xy:?}");
        let step = (xy[1].0 - xy[0].0, xy[1].1 - xy[0].1);
        assert!(step.0 > 50.0 && step.1 < -50.0, "{xy:?}");
        assert!((xy[2].0 - xy[1].0 - step.0).abs() <= 1.0, "{xy:?}");
        assert!((xy[2].1 - xy[1].1 - step.1).abs() <= 1.0, "{xy:?}");
    }
}
