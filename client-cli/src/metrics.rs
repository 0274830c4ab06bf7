//! The service's status as data for machines: one JSON object (`status --json`), and the
//! Prometheus text exposition format (`metrics`, format version 0.0.4) for a node-exporter
//! textfile collector or a timer, so that no network listener runs in the real-time process.

use std::fmt::Write;

use std::time::{Duration, SystemTime};

use hexacomp_client::{Status, Telemetry};

/// The status of `instance` as one JSON object: the fields of [`Status`], the uptime in
/// seconds.
pub fn status_json(instance: &str, status: &Status) -> serde_json::Value {
    serde_json::json!({
        "instance": instance,
        "geometry_name": status.geometry_name,
        "geometry_fingerprint": status.geometry_fingerprint,
        "generation": status.generation,
        "model": status.model,
        "requests": status.requests,
        "points": status.points,
        "errors": status.errors,
        "overloaded": status.overloaded,
        "persist_failures": status.persist_failures,
        "uptime_s": status.uptime.as_secs_f64(),
        "wait_mode": status.wait_mode,
    })
}

/// The metrics of `instance` in the Prometheus text format: `hexacomp_up 1` and the service's
/// counters when it answered (`status`), `hexacomp_up 0` alone when it did not (`None`). The
/// instance is the label `hexacomp_instance` (Prometheus sets `instance` itself, to the
/// exporter's address, and would rename ours).
pub fn prometheus_text(instance: &str, status: Option<&Status>) -> String {
    let instance = format!("hexacomp_instance=\"{}\"", label_value(instance));
    let mut text = String::new();
    let mut metric = |name: &str, kind: &str, help: &str, labels: &str, value: String| {
        write_metric(&mut text, name, kind, help, labels, &value)
    };
    metric(
        "hexacomp_up",
        "gauge",
        "1 when the service answered the status request, 0 when it did not.",
        &instance,
        u8::from(status.is_some()).to_string(),
    );
    let Some(s) = status else {
        return text;
    };
    metric(
        "hexacomp_info",
        "gauge",
        "The geometry served and how the serving thread waits (the value is always 1).",
        &format!(
            "{instance},geometry=\"{}\",geometry_fingerprint=\"{}\",wait_mode=\"{}\"",
            label_value(&s.geometry_name),
            label_value(&s.geometry_fingerprint),
            label_value(s.wait_mode)
        ),
        "1".into(),
    );
    metric(
        "hexacomp_model_generation",
        "gauge",
        "Generation of the model serving (0: none; the points are answered no_model).",
        &instance,
        s.generation.to_string(),
    );
    for (name, help, value) in [
        (
            "hexacomp_requests_total",
            "Compensation requests served (their points computed) since the service started.",
            s.requests,
        ),
        (
            "hexacomp_points_total",
            "Points answered since the service started.",
            s.points,
        ),
        (
            "hexacomp_request_errors_total",
            "Requests refused (other protocol, unknown kind, batch too large), answers that \
             could not be sent, and requests that could not be received.",
            s.errors,
        ),
        (
            "hexacomp_overloaded_total",
            "Requests answered Overloaded (a client over its budget while others waited).",
            s.overloaded,
        ),
        (
            "hexacomp_persist_failures_total",
            "Accepted models that could not be written to the state directory (a restart \
             would serve an older model).",
            s.persist_failures,
        ),
    ] {
        metric(name, "counter", help, &instance, value.to_string());
    }
    metric(
        "hexacomp_uptime_seconds",
        "gauge",
        "Seconds since the service started.",
        &instance,
        format!("{:.3}", s.uptime.as_secs_f64()),
    );
    text
}

/// The telemetry of `instance` in the Prometheus text format, to follow [`prometheus_text`]'s
/// lines: the answer times as the histogram `hexacomp_answer_duration_seconds` (cumulative
/// buckets, sum, count: `histogram_quantile` gives the percentiles), the deadline and the
/// answers that missed it, and the model's age at `now` (none without a model; 0 when `now` is
/// before the deploy, a clock set back).
pub fn telemetry_text(instance: &str, telemetry: &Telemetry, now: SystemTime) -> String {
    let labels = format!("hexacomp_instance=\"{}\"", label_value(instance));
    let mut text = String::new();
    let name = "hexacomp_answer_duration_seconds";
    let _ = writeln!(
        text,
        "# HELP {name} Served compensation requests of at most 64 points, by the time from \
         the serving thread receiving each to sending its answer (the service's part of a \
         round trip: not its wake-up, not the client's side)."
    );
    let _ = writeln!(text, "# TYPE {name} histogram");
    let mut answers = 0;
    for (bound, count) in &telemetry.answer_times {
        answers += count;
        let le = bound.map_or("+Inf".to_string(), |b| b.as_secs_f64().to_string());
        let _ = writeln!(text, "{name}_bucket{{{labels},le=\"{le}\"}} {answers}");
    }
    let sum = telemetry.answer_time_sum.as_secs_f64();
    let _ = writeln!(text, "{name}_sum{{{labels}}} {sum}");
    let _ = writeln!(text, "{name}_count{{{labels}}} {answers}");
    write_metric(
        &mut text,
        "hexacomp_deadline_seconds",
        "gauge",
        "The service's deadline for answering a request (--deadline-us).",
        &labels,
        &telemetry.deadline.as_secs_f64().to_string(),
    );
    write_metric(
        &mut text,
        "hexacomp_deadline_misses_total",
        "counter",
        "Timed answers (hexacomp_answer_duration_seconds) later than the deadline.",
        &labels,
        &telemetry.deadline_misses.to_string(),
    );
    if let Some(since) = telemetry.model_since {
        let accepted = since
            .duration_since(SystemTime::UNIX_EPOCH)
            .unwrap_or(Duration::ZERO);
        write_metric(
            &mut text,
            "hexacomp_model_accepted_timestamp_seconds",
            "gauge",
            "When the model serving was accepted (deployed, or loaded at the start), seconds \
             since the Unix epoch: `time() - hexacomp_model_accepted_timestamp_seconds` is its age.",
            &labels,
            &format!("{:.3}", accepted.as_secs_f64()),
        );
        let age = now.duration_since(since).unwrap_or(Duration::ZERO);
        write_metric(
            &mut text,
            "hexacomp_model_age_seconds",
            "gauge",
            "Seconds since the model serving was accepted, when this file was written.",
            &labels,
            &format!("{:.3}", age.as_secs_f64()),
        );
    }
    text
}

/// One sample with its HELP and TYPE lines.
fn write_metric(text: &mut String, name: &str, kind: &str, help: &str, labels: &str, value: &str) {
    let _ = writeln!(text, "# HELP {name} {help}");
    let _ = writeln!(text, "# TYPE {name} {kind}");
    let _ = writeln!(text, "{name}{{{labels}}} {value}");
}

/// `value` as a Prometheus label value: backslash, double quote and line feed escaped.
fn label_value(value: &str) -> String {
    value
        .replace('\\', "\\\\")
        .replace('"', "\\\"")
        .replace('\n', "\\n")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn status() -> Status {
        Status {
            geometry_fingerprint: "6dbc9d4c037e4df1".into(),
            geometry_name: "proto \"A\"\\1\nB".into(),
            generation: 3,
            model: "calibrate 2026-11-24".into(),
            requests: 10,
            points: 1034,
            errors: 1,
            overloaded: 2,
            persist_failures: 0,
            uptime: Duration::from_millis(12_345),
            wait_mode: "spin",
        }
    }

    /// The samples of a text: `(name, labels, value)`, each line checked against the format.
    fn samples(text: &str) -> Vec<(String, String, f64)> {
        let mut described = Vec::new();
        let mut found = Vec::new();
        for line in text.lines() {
            if let Some(rest) = line.strip_prefix("# TYPE ") {
                let (name, kind) = rest.split_once(' ').unwrap();
                assert!(["gauge", "counter"].contains(&kind), "{line}");
                described.push(name.to_string());
            } else if !line.starts_with("# HELP ") {
                let open = line.find('{').unwrap();
                let close = line.rfind("} ").unwrap();
                let name = &line[..open];
                assert_eq!(described.last().map(String::as_str), Some(name), "{line}");
                found.push((
                    name.to_string(),
                    line[open + 1..close].to_string(),
                    line[close + 2..].parse().unwrap(),
                ));
            }
        }
        found
    }

    #[test]
    fn every_counter_is_a_sample_with_its_type_and_labels_escaped() {
        let text = prometheus_text("machine-1", Some(&status()));
        let samples = samples(&text);
        let value = |name: &str| samples.iter().find(|s| s.0 == name).unwrap().2;
        assert_eq!(value("hexacomp_up"), 1.0);
        assert_eq!(value("hexacomp_model_generation"), 3.0);
        assert_eq!(value("hexacomp_requests_total"), 10.0);
        assert_eq!(value("hexacomp_points_total"), 1034.0);
        assert_eq!(value("hexacomp_request_errors_total"), 1.0);
        assert_eq!(value("hexacomp_overloaded_total"), 2.0);
        assert_eq!(value("hexacomp_persist_failures_total"), 0.0);
        assert_eq!(value("hexacomp_uptime_seconds"), 12.345);
        let info = samples.iter().find(|s| s.0 == "hexacomp_info").unwrap();
        assert!(
            info.1.contains(r#"geometry="proto \"A\"\\1\nB""#),
            "{}",
            info.1
        );
        assert!(
            samples
                .iter()
                .all(|s| s.1.starts_with("hexacomp_instance=\"machine-1\""))
        );
        // Every metric described once, and the text ends with a line feed.
        let types = text.lines().filter(|l| l.starts_with("# TYPE ")).count();
        let helps = text.lines().filter(|l| l.starts_with("# HELP ")).count();
        assert_eq!((types, helps), (samples.len(), samples.len()));
        assert!(text.ends_with('\n'));
    }

    #[test]
    fn a_service_that_does_not_answer_is_up_0_and_nothing_else() {
        let samples = samples(&prometheus_text("gone", None));
        assert_eq!(
            samples,
            [(
                "hexacomp_up".into(),
                "hexacomp_instance=\"gone\"".into(),
                0.0
            )]
        );
    }

    #[test]
    fn the_json_status_has_every_field() {
        let json = status_json("machine-1", &status());
        assert_eq!(json["instance"], "machine-1");
        assert_eq!(json["generation"], 3);
        assert_eq!(json["points"], 1034);
        assert_eq!(json["uptime_s"], 12.345);
        assert_eq!(json["wait_mode"], "spin");
        assert_eq!(json.as_object().unwrap().len(), 12);
    }

    fn telemetry(model_since: Option<SystemTime>) -> Telemetry {
        let mut answer_times: Vec<_> = (0..20)
            .map(|i| (Some(Duration::from_nanos(1 << (i + 8))), 0))
            .collect();
        answer_times[19].0 = None;
        answer_times[2].1 = 5; // up to 1.024 µs
        answer_times[10].1 = 2; // up to 262.144 µs
        answer_times[19].1 = 1; // beyond 67 ms
        Telemetry {
            deadline: Duration::from_micros(200),
            deadline_misses: 3,
            model_since,
            answer_times,
            answer_time_sum: Duration::from_micros(70_400),
        }
    }

    #[test]
    fn the_answer_times_are_a_cumulative_histogram_with_the_deadline_and_the_models_age() {
        let since = SystemTime::UNIX_EPOCH + Duration::from_secs(1_000_000);
        let now = since + Duration::from_millis(3_600_250);
        let text = telemetry_text("m\"1", &telemetry(Some(since)), now);
        let value = |prefix: &str| -> f64 {
            let line = text
                .lines()
                .find(|l| l.starts_with(prefix))
                .unwrap_or_else(|| panic!("no {prefix} in\n{text}"));
            line.rsplit_once(' ').unwrap().1.parse().unwrap()
        };
        let bucket = |le: &str| {
            value(&format!(
                "hexacomp_answer_duration_seconds_bucket{{hexacomp_instance=\"m\\\"1\",le=\"{le}\"}}"
            ))
        };
        assert_eq!(bucket("0.000000256"), 0.0);
        assert_eq!(bucket("0.000001024"), 5.0);
        assert_eq!(bucket("0.000131072"), 5.0);
        assert_eq!(bucket("0.000262144"), 7.0);
        assert_eq!(bucket("0.067108864"), 7.0);
        assert_eq!(bucket("+Inf"), 8.0);
        assert_eq!(value("hexacomp_answer_duration_seconds_count"), 8.0);
        assert_eq!(value("hexacomp_answer_duration_seconds_sum"), 0.0704);
        assert_eq!(value("hexacomp_deadline_seconds"), 0.0002);
        assert_eq!(value("hexacomp_deadline_misses_total"), 3.0);
        assert_eq!(value("hexacomp_model_age_seconds"), 3600.25);
        assert_eq!(
            value("hexacomp_model_accepted_timestamp_seconds"),
            1_000_000.0
        );
        assert_eq!(
            text.lines()
                .filter(|l| l.starts_with("hexacomp_answer_duration_seconds_bucket"))
                .count(),
            20
        );
        assert!(text.contains("# TYPE hexacomp_answer_duration_seconds histogram\n"));
        // Without a model, no age; with a clock set back, 0.
        let text = telemetry_text("m", &telemetry(None), now);
        assert!(!text.contains("hexacomp_model_"), "{text}");
        let text = telemetry_text("m", &telemetry(Some(now)), since);
        assert!(text.contains("hexacomp_model_age_seconds{hexacomp_instance=\"m\"} 0.000\n"));
    }
}
