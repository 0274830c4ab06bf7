//! Minimal SVG line and scatter charts for the trainer's reports: axes with ticks, labelled
//! series, optional error bars. Hand-written so that reports need no font or system library.

use std::fmt::Write;

/// One series of a chart.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Points `(x, y)`.
    pub points: Vec<(f64, f64)>,
    /// Optional half-height of an error bar per point (same length as `points`).
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

/// A chart: title, axis labels and series.
#[derive(Debug, Clone)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// Label of the x axis.
    pub x_label: String,
    /// Label of the y axis.
    pub y_label: String,
    /// The series, drawn in order.
    pub series: Vec<Series>,
}

const WIDTH: f64 = 800.0;
const HEIGHT: f64 = 480.0;
const LEFT: f64 = 80.0;
const RIGHT: f64 = 200.0;
const TOP: f64 = 50.0;
const BOTTOM: f64 = 60.0;
const COLOURS: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
];

impl Chart {
    /// The chart as an SVG document.
    pub fn to_svg(&self) -> String {
        let all: Vec<(f64, f64, f64)> =
            self.series
                .iter()
                .flat_map(|s| {
                    s.points.iter().enumerate().map(move |(i, &(x, y))| {
                        (x, y, s.error_bars.as_ref().map_or(0.0, |e| e[i]))
                    })
                })
                .filter(|(x, y, _)| x.is_finite() && y.is_finite())
                .collect();
        let (x_lo, x_hi) = nice_range(all.iter().map(|p| p.0));
        let (y_lo, y_hi) = nice_range(
            all.iter()
                .flat_map(|p| [p.1 - p.2, p.1 + p.2])
                .chain(std::iter::once(0.0)),
        );
        let plot_w = WIDTH - LEFT - RIGHT;
        let plot_h = HEIGHT - TOP - BOTTOM;
        let px = |x: f64| LEFT + (x - x_lo) / (x_hi - x_lo) * plot_w;
        let py = |y: f64| TOP + plot_h - (y - y_lo) / (y_hi - y_lo) * plot_h;

        let mut svg = String::new();
        let _ = write!(
            svg,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{HEIGHT}" font-family="sans-serif" font-size="12">"#
        );
        let _ = write!(svg, r#"<rect width="100%" height="100%" fill="white"/>"#);
        let _ = write!(
            svg,
            r#"<text x="{}" y="28" text-anchor="middle" font-size="16">{}</text>"#,
            LEFT + plot_w / 2.0,
            escape(&self.title)
        );
        for tick in ticks(x_lo, x_hi) {
            let x = px(tick);
            let _ = write!(
                svg,
                r##"<line x1="{x:.1}" y1="{TOP}" x2="{x:.1}" y2="{:.1}" stroke="#eee"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
                TOP + plot_h,
                TOP + plot_h + 18.0,
                format_tick(tick)
            );
        }
        for tick in ticks(y_lo, y_hi) {
            let y = py(tick);
            let _ = write!(
                svg,
                r##"<line x1="{LEFT}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#eee"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
                LEFT + plot_w,
                LEFT - 6.0,
                y + 4.0,
                format_tick(tick)
            );
        }
        let _ = write!(
            svg,
            r#"<rect x="{LEFT}" y="{TOP}" width="{plot_w}" height="{plot_h}" fill="none" stroke="black"/>"#
        );
        let _ = write!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
            LEFT + plot_w / 2.0,
            HEIGHT - 15.0,
            escape(&self.x_label)
        );
        let _ = write!(
            svg,
            r#"<text transform="translate(20,{:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
            TOP + plot_h / 2.0,
            escape(&self.y_label)
        );
        for (index, series) in self.series.iter().enumerate() {
            let colour = COLOURS[index % COLOURS.len()];
            let finite: Vec<(usize, f64, f64)> = series
                .points
                .iter()
                .enumerate()
                .filter(|(_, (x, y))| x.is_finite() && y.is_finite())
                .map(|(i, &(x, y))| (i, x, y))
                .collect();
            if !series.markers_only && finite.len() > 1 {
                let path: Vec<String> = finite
                    .iter()
                    .map(|(_, x, y)| format!("{:.1},{:.1}", px(*x), py(*y)))
                    .collect();
                let _ = write!(
                    svg,
                    r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="1.5"/>"#,
                    path.join(" ")
                );
            }
            for &(i, x, y) in &finite {
                let _ = write!(
                    svg,
                    r#"<circle cx="{:.1}" cy="{:.1}" r="2.5" fill="{colour}"/>"#,
                    px(x),
                    py(y)
                );
                if let Some(bars) = &series.error_bars {
                    let _ = write!(
                        svg,
                        r#"<line x1="{0:.1}" y1="{1:.1}" x2="{0:.1}" y2="{2:.1}" stroke="{colour}"/>"#,
                        px(x),
                        py(y - bars[i]),
                        py(y + bars[i])
                    );
                }
            }
            let ly = TOP + 10.0 + 18.0 * index as f64;
            let lx = LEFT + plot_w + 15.0;
            let _ = write!(
                svg,
                r#"<line x1="{lx}" y1="{ly}" x2="{}" y2="{ly}" stroke="{colour}" stroke-width="3"/><text x="{}" y="{}">{}</text>"#,
                lx + 20.0,
                lx + 26.0,
                ly + 4.0,
                escape(&series.label)
            );
        }
        svg.push_str("</svg>\n");
        svg
    }
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// A range covering `values`, widened to round tick steps.
fn nice_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-12 {
        return (lo - 0.5, hi + 0.5);
    }
    let step = tick_step(lo, hi);
    ((lo / step).floor() * step, (hi / step).ceil() * step)
}

fn tick_step(lo: f64, hi: f64) -> f64 {
    let raw = (hi - lo) / 6.0;
    let magnitude = 10f64.powf(raw.log10().floor());
    let fraction = raw / magnitude;
    magnitude
        * if fraction < 1.5 {
            1.0
        } else if fraction < 3.5 {
            2.0
        } else if fraction < 7.5 {
            5.0
        } else {
            10.0
        }
}

fn ticks(lo: f64, hi: f64) -> Vec<f64> {
    let step = tick_step(lo, hi);
    let mut out = Vec::new();
    let mut t = (lo / step).ceil() * step;
    while t <= hi + step * 1e-9 {
        out.push(if t.abs() < step * 1e-9 { 0.0 } else { t });
        t += step;
    }
    out
}

fn format_tick(value: f64) -> String {
    let text = format!("{value:.6}");
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_and_cover_the_range() {
        let (lo, hi) = nice_range([0.013, 0.087].into_iter());
        assert_eq!((lo, hi), (0.01, 0.09));
        assert_eq!(ticks(lo, hi).len(), 9);
        assert_eq!(format_tick(0.05), "0.05");
    }

    #[test]
    fn chart_has_every_series_and_escapes_labels() {
        let chart = Chart {
            title: "RMSE <mm>".into(),
            x_label: "hidden nodes".into(),
            y_label: "RMSE (mm)".into(),
            series: vec![
                Series::line("training", vec![(1.0, 0.2), (2.0, 0.1)]),
                Series::line("validation", vec![(1.0, 0.25), (2.0, 0.15)]),
            ],
        };
        let svg = chart.to_svg();
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>\n"));
        assert_eq!(svg.matches("<polyline").count(), 2);
        assert!(svg.contains("RMSE &lt;mm&gt;") && svg.contains(">validation<"));
    }
}
