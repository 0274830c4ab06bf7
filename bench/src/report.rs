//! Reports of a benchmark: latency percentiles per variant, the `.hgrm` percentile distribution
//! (HdrHistogram's text format, values in microseconds), SVG plots and the JSON summary.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context;
use hdrhistogram::Histogram;
use hexacomp_core::durable::replace_file;
use hexacomp_report::chart::{Axis, Chart, Series};
use serde::Serialize;

use crate::stream::StreamRun;

/// One variant's figures, as written to the JSON summary.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Summary {
    /// Median round trip, ns.
    pub p50_ns: u64,
    /// 90th percentile, ns.
    pub p90_ns: u64,
    /// 99th percentile, ns.
    pub p99_ns: u64,
    /// 99.9th percentile, ns.
    pub p999_ns: u64,
    /// 99.99th percentile, ns.
    pub p9999_ns: u64,
    /// Largest round trip, ns.
    pub max_ns: u64,
    /// Points streamed.
    pub points: u64,
    /// Requests whose round trip exceeded the interpolation period.
    pub deadline_misses: u64,
}

impl Summary {
    /// The figures of a histogram of round trips (ns).
    pub fn of(histogram: &Histogram<u64>, points: usize, deadline_misses: usize) -> Self {
        Self {
            p50_ns: histogram.value_at_quantile(0.5),
            p90_ns: histogram.value_at_quantile(0.9),
            p99_ns: histogram.value_at_quantile(0.99),
            p999_ns: histogram.value_at_quantile(0.999),
            p9999_ns: histogram.value_at_quantile(0.9999),
            max_ns: histogram.max(),
            points: points as u64,
            deadline_misses: deadline_misses as u64,
        }
    }

    /// The figures of a stream (requests outside model swaps).
    pub fn of_run(run: &StreamRun) -> Self {
        Self::of(&run.histogram, run.points, run.deadline_misses)
    }
}

/// The JSON summary: `{"variants": {NAME: Summary}}`.
#[derive(Debug, Default, Serialize)]
pub struct JsonSummary {
    /// Figures per variant name.
    pub variants: BTreeMap<String, Summary>,
}

impl JsonSummary {
    /// Writes the summary to `path`.
    pub fn write(&self, path: &Path) -> anyhow::Result<()> {
        write_json(path, self)
    }
}

/// Writes `value` to `path` as indented JSON, whole or not at all.
pub fn write_json(path: &Path, value: &impl Serialize) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    replace_file(path, (text + "\n").as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

fn micros(ns: u64) -> String {
    format!("{:.2}", ns as f64 / 1e3)
}

/// A table of latency percentiles (µs) and throughput, one row per variant.
pub fn latency_table(rows: &[(&str, Summary, f64)]) -> String {
    let mut table = hexacomp_report::table::Table::new([
        "variant",
        "p50 µs",
        "p90 µs",
        "p99 µs",
        "p99.9 µs",
        "p99.99 µs",
        "max µs",
        "points",
        "points/s",
        "misses",
    ]);
    for (name, s, rate) in rows {
        table.row([
            name.to_string(),
            micros(s.p50_ns),
            micros(s.p90_ns),
            micros(s.p99_ns),
            micros(s.p999_ns),
            micros(s.p9999_ns),
            micros(s.max_ns),
            s.points.to_string(),
            format!("{rate:.0}"),
            s.deadline_misses.to_string(),
        ]);
    }
    table.to_string()
}

/// HdrHistogram's percentile distribution text (values in µs, five ticks per half distance),
/// readable by HdrHistogram's plotter.
pub fn percentile_distribution(histogram: &Histogram<u64>) -> String {
    let mut text = String::new();
    let _ = writeln!(
        text,
        "{:>12} {:>14} {:>10} {:>14}\n",
        "Value", "Percentile", "TotalCount", "1/(1-Percentile)"
    );
    let mut total = 0u64;
    for step in histogram.iter_quantiles(5) {
        total += step.count_since_last_iteration();
        let quantile = step.quantile_iterated_to();
        let value = step.value_iterated_to() as f64 / 1e3;
        if quantile < 1.0 {
            let _ = writeln!(
                text,
                "{value:12.3} {quantile:2.12} {total:10} {:14.2}",
                1.0 / (1.0 - quantile)
            );
        } else {
            let _ = writeln!(text, "{value:12.3} {quantile:2.12} {total:10}");
        }
    }
    let _ = writeln!(
        text,
        "#[Mean    = {:12.3}, StdDeviation   = {:12.3}]",
        histogram.mean() / 1e3,
        histogram.stdev() / 1e3
    );
    let _ = writeln!(
        text,
        "#[Max     = {:12.3}, Total count    = {:12}]",
        histogram.max() as f64 / 1e3,
        histogram.len()
    );
    let _ = writeln!(
        text,
        "#[Buckets = {:12}, SubBuckets     = {:12}]",
        histogram.buckets(),
        histogram.distinct_values()
    );
    text
}

/// The latency percentile curves of several histograms on the usual axes: the percentile on a
/// log scale of 1/(1−p) (90 %, 99 %, 99.9 % equally spaced) and the round trip (µs) on a log
/// scale. Each curve ends at its maximum, placed at the percentile of its last recorded value
/// (1 − 1/count).
pub fn percentile_chart(title: &str, curves: &[(&str, &Histogram<u64>)]) -> Chart {
    let series = curves
        .iter()
        .map(|(name, histogram)| {
            let last = 1.0 - 1.0 / histogram.len().max(1) as f64;
            let points = (0..)
                .map(|k| 1.0 - 10f64.powf(-0.1 * f64::from(k)))
                .take_while(|&quantile| quantile < last)
                .map(|quantile| {
                    let us = histogram.value_at_quantile(quantile) as f64 / 1e3;
                    (quantile, us)
                })
                .chain(std::iter::once((last, histogram.max() as f64 / 1e3)))
                .collect();
            Series::line(*name, points)
        })
        .collect();
    Chart {
        title: title.to_string(),
        x: Axis::percentile("percentile (the last point of a curve is its maximum)"),
        y: Axis::log("round trip (µs)"),
        series,
    }
}

/// Round trip along the path of each variant (`(name, latencies in ns)`, every variant
/// streamed along the same path): the maximum of each of about 500 stretches of the stream,
/// and the median of the first variant's, against the time along the path (s); log scale in µs.
pub fn along_path_chart(title: &str, runs: &[(&str, &[u32])], period_s: f64) -> Chart {
    let mut series = Vec::new();
    for (index, (name, latencies_ns)) in runs.iter().enumerate() {
        let stretch = latencies_ns.len().div_ceil(500).max(1);
        let mut medians = Vec::new();
        let mut maxima = Vec::new();
        for (k, chunk) in latencies_ns.chunks(stretch).enumerate() {
            let mut sorted = chunk.to_vec();
            sorted.sort_unstable();
            let t = (k * stretch) as f64 * period_s;
            medians.push((t, f64::from(sorted[sorted.len() / 2]) / 1e3));
            maxima.push((
                t,
                f64::from(*sorted.last().expect("chunks are not empty")) / 1e3,
            ));
        }
        series.push(Series::line(format!("{name}: max of {stretch}"), maxima));
        if index == 0 {
            series.push(Series::line(
                format!("{name}: median of {stretch}"),
                medians,
            ));
        }
    }
    Chart {
        title: title.to_string(),
        x: Axis::linear("time along the path (s)"),
        y: Axis::log("round trip (µs)"),
        series,
    }
}

/// Writes `text` to `dir/name` and returns the path written.
pub fn write_into(dir: &Path, name: &str, text: &str) -> anyhow::Result<std::path::PathBuf> {
    let path = dir.join(name);
    replace_file(&path, text.as_bytes()).with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stream::new_histogram;

    fn known_histogram() -> Histogram<u64> {
        let mut histogram = new_histogram();
        for ns in 1..=10_000u64 {
            histogram.record(ns * 100).unwrap();
        }
        histogram
    }

    #[test]
    fn summary_percentiles_match_the_recorded_values() {
        let s = Summary::of(&known_histogram(), 10_000, 3);
        // 3 significant digits: within 0.1 %.
        for (got, want) in [
            (s.p50_ns, 500_000.0),
            (s.p90_ns, 900_000.0),
            (s.p99_ns, 990_000.0),
            (s.p999_ns, 999_000.0),
            (s.max_ns, 1_000_000.0),
        ] {
            assert!((got as f64 - want).abs() <= want * 1e-3, "{got} vs {want}");
        }
        let json = serde_json::to_value(JsonSummary {
            variants: [("hexacomp".to_string(), s)].into(),
        })
        .unwrap();
        assert_eq!(json["variants"]["hexacomp"]["deadline_misses"], 3);
        assert_eq!(json["variants"]["hexacomp"]["points"], 10_000);
        assert!(json["variants"]["hexacomp"]["p9999_ns"].is_u64());
    }

    #[test]
    fn percentile_curves_climb_the_nines_and_end_at_each_maximum() {
        let mut small = new_histogram();
        for ns in [1000, 2000, 3000, 4000] {
            small.record(ns).unwrap();
        }
        let chart = percentile_chart("t", &[("a", &known_histogram()), ("b", &small)]);
        assert_eq!(chart.series.len(), 2);
        let a = &chart.series[0].points;
        // 10 000 values: quantiles up to 99.9 %, every tenth of a nine, then the maximum at
        // 1 − 1/10 000.
        assert_eq!(a.len(), 41, "{a:?}");
        assert!((a[10].0 - 0.9).abs() < 1e-12 && (a[10].1 - 900.0).abs() <= 0.9);
        assert!((a[30].0 - 0.999).abs() < 1e-12 && (a[30].1 - 999.0).abs() <= 1.0);
        assert_eq!(
            *a.last().unwrap(),
            (0.9999, known_histogram().max() as f64 / 1e3)
        );
        let b = &chart.series[1].points;
        // Four values: 0 %, 10 %…, 68 % (below 1 − 1/4), then the maximum at 75 %.
        assert_eq!(b.last().unwrap().0, 0.75, "{b:?}");
        assert!((b.last().unwrap().1 - 4.0).abs() < 0.01, "{b:?}");
        assert!(
            b.windows(2).all(|w| w[1].0 > w[0].0 && w[1].1 >= w[0].1),
            "{b:?}"
        );
    }

    #[test]
    fn percentile_distribution_ends_at_the_total_count_and_the_maximum() {
        let text = percentile_distribution(&known_histogram());
        let rows: Vec<Vec<&str>> = text
            .lines()
            .skip(2)
            .take_while(|l| !l.starts_with('#'))
            .map(|l| l.split_whitespace().collect())
            .collect();
        let last = rows.last().unwrap();
        assert_eq!(last[1].parse::<f64>().unwrap(), 1.0);
        assert_eq!(last[2], "10000");
        assert!((last[0].parse::<f64>().unwrap() - 1000.0).abs() < 1.0);
        // Percentiles and counts never go down.
        for pair in rows.windows(2) {
            assert!(pair[1][1].parse::<f64>().unwrap() >= pair[0][1].parse::<f64>().unwrap());
            assert!(pair[1][2].parse::<u64>().unwrap() >= pair[0][2].parse::<u64>().unwrap());
        }
        assert!(text.contains("Total count    =        10000"));
    }
}
