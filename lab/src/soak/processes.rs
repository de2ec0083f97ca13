//! The processes of the graph under watch, their once-a-second readings, and the figures drawn
//! from them: resident memory at start/end/peak, its least-squares slope after the warm-up, and
//! CPU use.

use crate::procfs::{self, ProcReading};

/// One reading of a process at a time since the soak started.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// Seconds since the soak started.
    pub t_s: f64,
    /// Resident memory and CPU time.
    pub proc: ProcReading,
}

/// A process of the graph (a node, or the launcher) and its readings.
#[derive(Debug, Clone, PartialEq)]
pub struct Tracked {
    /// The node name, or `launcher`.
    pub label: String,
    /// Process id.
    pub pid: u32,
    /// Readings, oldest first.
    pub readings: Vec<Reading>,
    /// True once reading it failed (the process ended).
    pub gone: bool,
}

impl Tracked {
    /// A process not read yet.
    pub fn new(label: &str, pid: u32) -> Self {
        Self {
            label: label.to_owned(),
            pid,
            readings: Vec::new(),
            gone: false,
        }
    }

    /// Reads the process now; `None` (and marked gone) once it has ended.
    pub fn read(&mut self, t_s: f64) -> Option<Reading> {
        if self.gone {
            return None;
        }
        match procfs::read(self.pid) {
            Ok(proc) => {
                let reading = Reading { t_s, proc };
                self.readings.push(reading);
                Some(reading)
            }
            Err(_) => {
                self.gone = true;
                None
            }
        }
    }
}

/// What a process did over the measurement window.
#[derive(Debug, Clone, PartialEq)]
pub struct Figures {
    /// The node name, or `launcher`.
    pub label: String,
    /// Process id.
    pub pid: u32,
    /// Resident memory at the first reading of the window, KiB.
    pub rss_start_kib: u64,
    /// Resident memory at the last reading, KiB.
    pub rss_end_kib: u64,
    /// Largest resident memory in the window, KiB.
    pub rss_max_kib: u64,
    /// Least-squares slope of resident memory over the readings after the warm-up, KiB per
    /// minute; `None` with fewer than [`MIN_SLOPE_READINGS`] readings.
    pub rss_slope_kib_per_min: Option<f64>,
    /// Readings the slope was fitted to.
    pub slope_readings: usize,
    /// CPU time over wall time in the window, % of one core; `None` with one reading.
    pub cpu_percent: Option<f64>,
}

/// Fewest readings after the warm-up to fit a memory slope to.
pub const MIN_SLOPE_READINGS: usize = 5;

/// The figures of `tracked` over the window starting at `window_start_s`, its memory slope
/// fitted from `warm_up_end_s` on; `None` if it has no reading in the window.
pub fn figures(
    tracked: &Tracked,
    window_start_s: f64,
    warm_up_end_s: f64,
    ticks_per_second: u64,
) -> Option<Figures> {
    let window: Vec<&Reading> = tracked
        .readings
        .iter()
        .filter(|r| r.t_s >= window_start_s)
        .collect();
    let (first, last) = (window.first()?, window.last()?);
    let after_warm_up: Vec<(f64, f64)> = window
        .iter()
        .filter(|r| r.t_s >= warm_up_end_s)
        .map(|r| (r.t_s / 60.0, r.proc.rss_kib as f64))
        .collect();
    let rss_slope_kib_per_min = if after_warm_up.len() >= MIN_SLOPE_READINGS {
        least_squares_slope(&after_warm_up)
    } else {
        None
    };
    let wall_s = last.t_s - first.t_s;
    let cpu_percent = (wall_s > 0.0).then(|| {
        let cpu_s = last.proc.cpu_ticks.saturating_sub(first.proc.cpu_ticks) as f64
            / ticks_per_second as f64;
        100.0 * cpu_s / wall_s
    });
    Some(Figures {
        label: tracked.label.clone(),
        pid: tracked.pid,
        rss_start_kib: first.proc.rss_kib,
        rss_end_kib: last.proc.rss_kib,
        rss_max_kib: window.iter().map(|r| r.proc.rss_kib).max().unwrap_or(0),
        rss_slope_kib_per_min,
        slope_readings: after_warm_up.len(),
        cpu_percent,
    })
}

/// Slope of the least-squares line through `points` (x, y); `None` if the x are all equal.
pub fn least_squares_slope(points: &[(f64, f64)]) -> Option<f64> {
    let n = points.len() as f64;
    let mean_x = points.iter().map(|p| p.0).sum::<f64>() / n;
    let mean_y = points.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = points.iter().map(|p| (p.0 - mean_x).powi(2)).sum();
    let sxy: f64 = points.iter().map(|p| (p.0 - mean_x) * (p.1 - mean_y)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reading(t_s: f64, rss_kib: u64, cpu_ticks: u64) -> Reading {
        Reading {
            t_s,
            proc: ProcReading { rss_kib, cpu_ticks },
        }
    }

    #[test]
    fn slope_of_a_line_and_of_noise_about_it() {
        let line: Vec<(f64, f64)> = (0..10)
            .map(|i| (f64::from(i), 3.0 * f64::from(i) + 7.0))
            .collect();
        assert!((least_squares_slope(&line).unwrap() - 3.0).abs() < 1e-12);
        let zigzag: Vec<(f64, f64)> = (0..10)
            .map(|i| (f64::from(i), if i % 2 == 0 { 100.0 } else { 104.0 }))
            .collect();
        assert!(least_squares_slope(&zigzag).unwrap().abs() < 0.5);
        assert_eq!(least_squares_slope(&[(1.0, 2.0), (1.0, 3.0)]), None);
    }

    #[test]
    fn figures_skip_start_up_and_fit_after_the_warm_up() {
        let mut tracked = Tracked::new("encoders", 42);
        // Start-up growth before the window, a warm-up step, then +60 KiB per second.
        tracked.readings.push(reading(0.0, 1_000, 0));
        tracked.readings.push(reading(10.0, 5_000, 100));
        tracked.readings.push(reading(11.0, 9_000, 150));
        for i in 0..10u64 {
            tracked
                .readings
                .push(reading(20.0 + i as f64, 10_000 + 60 * i, 200 + 25 * i));
        }
        let figures = figures(&tracked, 10.0, 20.0, 100).unwrap();
        assert_eq!(figures.rss_start_kib, 5_000);
        assert_eq!(figures.rss_end_kib, 10_540);
        assert_eq!(figures.rss_max_kib, 10_540);
        assert_eq!(figures.slope_readings, 10);
        let slope = figures.rss_slope_kib_per_min.unwrap();
        assert!((slope - 3_600.0).abs() < 1e-6, "{slope}");
        // (425 - 100) ticks = 3.25 s of CPU over 19 s.
        let cpu = figures.cpu_percent.unwrap();
        assert!((cpu - 100.0 * 3.25 / 19.0).abs() < 1e-9, "{cpu}");
    }

    #[test]
    fn too_few_readings_give_no_slope() {
        let mut tracked = Tracked::new("rig", 7);
        assert!(figures(&tracked, 0.0, 0.0, 100).is_none());
        tracked.readings.push(reading(1.0, 100, 0));
        tracked.readings.push(reading(2.0, 100, 0));
        let figures = figures(&tracked, 0.0, 0.0, 100).unwrap();
        assert_eq!(figures.rss_slope_kib_per_min, None);
        assert_eq!(figures.cpu_percent, Some(0.0));
    }
}
