//! What a bench run writes: one `.hgrm` percentile distribution per measurement, `bench.csv`,
//! and the table printed on stdout.

use super::cpu::CpuShare;
use super::hops::{Outcome, IDLE_CPU_LIMIT_CORES};
use super::stats::{format_ns, Measurement, Summary};
use anyhow::Context;
use hdrhistogram::Histogram;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Name of the CSV file with one row per measurement.
pub const CSV_FILE: &str = "bench.csv";

/// Name of the CSV file with the idle CPU use of the measured processes.
pub const IDLE_CSV_FILE: &str = "idle-cpu.csv";

/// Header of [`CSV_FILE`].
pub const CSV_HEADER: [&str; 8] = ["name", "unit", "count", "p50", "p90", "p99", "p999", "max"];

/// Ticks per half distance of the `.hgrm` percentile iteration (HdrHistogram's default).
const HGRM_TICKS_PER_HALF_DISTANCE: u32 = 5;

/// `.hgrm` values are written in thousandths of the measured unit (µs for ns).
const HGRM_SCALE: f64 = 1_000.0;

/// The classic HdrHistogram percentile distribution text (`outputPercentileDistribution`,
/// readable by HdrHistogram's plotter): values divided by `scale`, percentiles as fractions,
/// cumulative counts, and the mean/max/bucket footer.
pub fn hgrm_text(histogram: &Histogram<u64>, scale: f64) -> String {
    let digits = usize::from(histogram.sigfig());
    let mut text = format!(
        "{:>12} {:>14} {:>10} {:>14}\n\n",
        "Value", "Percentile", "TotalCount", "1/(1-Percentile)"
    );
    if !histogram.is_empty() {
        let mut total = 0u64;
        for step in histogram.iter_quantiles(HGRM_TICKS_PER_HALF_DISTANCE) {
            total += step.count_since_last_iteration();
            let value = step.value_iterated_to() as f64 / scale;
            let quantile = step.quantile_iterated_to();
            // Writing to a String cannot fail.
            if quantile < 1.0 {
                let _ = writeln!(
                    text,
                    "{value:12.digits$} {quantile:2.12} {total:10} {:14.2}",
                    1.0 / (1.0 - quantile)
                );
            } else {
                let _ = writeln!(text, "{value:12.digits$} {quantile:2.12} {total:10}");
            }
        }
    }
    let mean = if histogram.is_empty() {
        0.0
    } else {
        histogram.mean() / scale
    };
    let stdev = if histogram.is_empty() {
        0.0
    } else {
        histogram.stdev() / scale
    };
    let max = histogram.max() as f64 / scale;
    let _ = writeln!(
        text,
        "#[Mean    = {mean:12.digits$}, StdDeviation   = {stdev:12.digits$}]"
    );
    let _ = writeln!(
        text,
        "#[Max     = {max:12.digits$}, Total count    = {:12}]",
        histogram.len()
    );
    let _ = writeln!(
        text,
        "#[Buckets = {:12}, SubBuckets     = {:12}]",
        histogram.buckets(),
        sub_bucket_count(histogram.sigfig())
    );
    text
}

/// Sub-buckets per bucket of a histogram with lowest value 1 and `sigfig` significant digits.
fn sub_bucket_count(sigfig: u8) -> u64 {
    (2 * 10u64.pow(u32::from(sigfig))).next_power_of_two()
}

/// The `.hgrm` file name of a measurement: its name with `/` replaced by `_`.
pub fn hgrm_file_name(name: &str) -> String {
    format!("{}.hgrm", name.replace('/', "_"))
}

/// Writes `<dir>/<name>.hgrm` (values in thousandths of the unit: µs for ns) for each
/// measurement and returns the paths.
pub fn write_hgrm_files(dir: &Path, measurements: &[Measurement]) -> anyhow::Result<Vec<PathBuf>> {
    measurements
        .iter()
        .map(|m| {
            let path = dir.join(hgrm_file_name(&m.name));
            std::fs::write(&path, hgrm_text(&m.histogram, HGRM_SCALE))
                .with_context(|| format!("cannot write {}", path.display()))?;
            Ok(path)
        })
        .collect()
}

/// Writes [`CSV_FILE`] rows `name,unit,count,p50,p90,p99,p999,max` (values in the unit).
pub fn write_csv(path: &Path, measurements: &[Measurement]) -> anyhow::Result<()> {
    let context = || format!("cannot write {}", path.display());
    let mut writer = csv::Writer::from_path(path).with_context(context)?;
    writer.write_record(CSV_HEADER).with_context(context)?;
    for m in measurements {
        let s = m.summary();
        let numbers = [s.count, s.p50, s.p90, s.p99, s.p999, s.max].map(|v| v.to_string());
        let mut row = vec![m.name.clone(), m.unit.to_owned()];
        row.extend(numbers);
        writer.write_record(&row).with_context(context)?;
    }
    writer.flush().with_context(context)
}

/// Writes [`IDLE_CSV_FILE`] rows `process,window_s,cpu_cores,resolution_cores` (1.0 = one
/// core busy).
pub fn write_idle_csv(path: &Path, shares: &[(String, CpuShare)]) -> anyhow::Result<()> {
    let context = || format!("cannot write {}", path.display());
    let mut writer = csv::Writer::from_path(path).with_context(context)?;
    writer
        .write_record(["process", "window_s", "cpu_cores", "resolution_cores"])
        .with_context(context)?;
    for (process, share) in shares {
        writer
            .write_record([
                process.clone(),
                format!("{:.3}", share.window.as_secs_f64()),
                format!("{:.4}", share.cores),
                format!("{:.4}", share.resolution),
            ])
            .with_context(context)?;
    }
    writer.flush().with_context(context)
}

/// The printed CPU table: one line per process (1.0 = one core busy) with the idle goal's
/// verdict, and what the labels mean.
pub fn idle_table(shares: &[(String, CpuShare)]) -> String {
    let mut text =
        format!("CPU use per process (1.0 = one core; idle goal ≤ {IDLE_CPU_LIMIT_CORES}):\n");
    for (process, share) in shares {
        let goal = Outcome::of(share.cores <= IDLE_CPU_LIMIT_CORES);
        let _ = writeln!(
            text,
            "  {process:<34} {:.3} (±{:.3} over {:.1} s): {goal}",
            share.cores,
            share.resolution,
            share.window.as_secs_f64()
        );
    }
    text.push_str(
        "  <transport>/<payload>: the baseline's pong waiting for a message; sensing/*: the \
         sensing graph streaming (rig autoplaying the session: it simulates the robot and \
         tracker at 2 kHz, never idle), the IK server without requests; setpoints/*: the rig \
         holding still without setpoints (it still simulates at 2 kHz); launcher: `sabr \
         launch` supervising\n",
    );
    text
}

/// The printed percentile table: one line per measurement.
pub fn percentile_table(measurements: &[Measurement]) -> String {
    let mut text = format!(
        "{:<34} {:>8} {:>12} {:>12} {:>12} {:>12} {:>12}  unit\n",
        "measurement", "count", "p50", "p90", "p99", "p99.9", "max"
    );
    for m in measurements {
        let Summary {
            count,
            p50,
            p90,
            p99,
            p999,
            max,
        } = m.summary();
        let shown = |v: u64| {
            if m.unit.starts_with("ns") {
                format_ns(v)
            } else {
                v.to_string()
            }
        };
        let _ = writeln!(
            text,
            "{:<34} {count:>8} {:>12} {:>12} {:>12} {:>12} {:>12}  {}",
            m.name,
            shown(p50),
            shown(p90),
            shown(p99),
            shown(p999),
            shown(max),
            m.unit
        );
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    fn uniform(name: &str) -> Measurement {
        let mut m = Measurement::new(name, "ns");
        for v in 1..=1000 {
            m.record(v).unwrap();
        }
        m
    }

    #[test]
    fn hgrm_has_header_monotone_rows_and_footer() {
        let m = uniform("a/b");
        let text = hgrm_text(&m.histogram, 1.0);
        let mut lines = text.lines();
        assert_eq!(
            lines.next().unwrap(),
            "       Value     Percentile TotalCount 1/(1-Percentile)"
        );
        assert_eq!(lines.next().unwrap(), "");
        let rows: Vec<Vec<f64>> = text
            .lines()
            .skip(2)
            .take_while(|l| !l.starts_with('#'))
            .map(|l| l.split_whitespace().map(|f| f.parse().unwrap()).collect())
            .collect();
        assert!(rows.len() > 10, "only {} rows", rows.len());
        assert_eq!(rows[0][..3], [1.0, 0.0, 1.0]);
        for pair in rows.windows(2) {
            assert!(pair[1][0] >= pair[0][0], "values not monotone: {pair:?}");
            assert!(
                pair[1][1] > pair[0][1],
                "percentiles not increasing: {pair:?}"
            );
            assert!(pair[1][2] >= pair[0][2], "counts not monotone: {pair:?}");
        }
        // The 50 % row: value 500 reached by 500 values, 1/(1-0.5) = 2.
        assert!(rows.contains(&vec![500.0, 0.5, 500.0, 2.0]), "{text}");
        // The last row is the maximum at percentile 1 with every value and no 4th column.
        assert_eq!(rows.last().unwrap(), &vec![1000.0, 1.0, 1000.0]);
        let footer: Vec<&str> = text.lines().filter(|l| l.starts_with('#')).collect();
        assert_eq!(
            footer,
            [
                "#[Mean    =      500.500, StdDeviation   =      288.675]",
                "#[Max     =     1000.000, Total count    =         1000]",
                "#[Buckets =            1, SubBuckets     =         2048]",
            ]
        );
    }

    #[test]
    fn hgrm_scales_values() {
        let mut m = Measurement::new("a/b", "ns");
        m.record(1500).unwrap();
        let text = hgrm_text(&m.histogram, 1000.0);
        assert!(
            text.contains("       1.500 1.000000000000          1\n"),
            "{text}"
        );
        assert!(text.contains("#[Max     =        1.500, Total count    =            1]"));
    }

    #[test]
    fn csv_rows_hold_the_summaries() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(CSV_FILE);
        let mut one = Measurement::new("compute/fk", "ns/solve");
        one.record(42).unwrap();
        write_csv(&path, &[uniform("uds/x"), one]).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(
            text,
            "name,unit,count,p50,p90,p99,p999,max\n\
             uds/x,ns,1000,500,900,990,999,1000\n\
             compute/fk,ns/solve,1,42,42,42,42,42\n"
        );
    }

    #[test]
    fn hgrm_files_are_named_after_measurements() {
        let dir = tempfile::tempdir().unwrap();
        let paths = write_hgrm_files(dir.path(), &[uniform("iox2-event/encoder-sample")]).unwrap();
        assert_eq!(paths, [dir.path().join("iox2-event_encoder-sample.hgrm")]);
        let text = std::fs::read_to_string(&paths[0]).unwrap();
        // Written in µs: the maximum 1000 ns is 1.000.
        assert!(text.contains("#[Max     =        1.000,"), "{text}");
    }

    #[test]
    fn idle_table_judges_each_process_against_the_goal() {
        let share = |cores| CpuShare {
            cores,
            resolution: 0.002,
            window: std::time::Duration::from_secs(5),
        };
        let table = idle_table(&[
            ("sensing/ik".to_owned(), share(0.004)),
            ("sensing/rig-autoplay".to_owned(), share(0.31)),
        ]);
        let lines: Vec<&str> = table.lines().collect();
        assert!(lines[0].contains("idle goal ≤ 0.05"), "{table}");
        assert!(
            lines[1].ends_with("sensing/ik                         0.004 (±0.002 over 5.0 s): met"),
            "{table}"
        );
        assert!(
            lines[2].ends_with("0.310 (±0.002 over 5.0 s): MISSED"),
            "{table}"
        );
    }

    #[test]
    fn idle_csv_rows_hold_the_shares() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(IDLE_CSV_FILE);
        let share = CpuShare {
            cores: 0.0123,
            resolution: 0.005,
            window: std::time::Duration::from_secs(2),
        };
        write_idle_csv(&path, &[("uds/ik".to_owned(), share)]).unwrap();
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "process,window_s,cpu_cores,resolution_cores\nuds/ik,2.000,0.0123,0.0050\n"
        );
    }

    #[test]
    fn table_lists_each_measurement_with_readable_values() {
        let table = percentile_table(&[uniform("uds/x")]);
        let row = table.lines().nth(1).unwrap();
        assert!(row.starts_with("uds/x "), "{row}");
        assert!(row.contains("990 ns"), "{row}");
        assert!(row.contains("1.000 µs"), "{row}");
    }
}
