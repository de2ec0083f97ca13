//! Tracker emulation, Polaris Vicra-like: frames at 20 Hz from the tracker's own clock, a
//! frame counter, noisy tool poses in the tracker frame `S` (depth noise larger than
//! lateral), per-tool RMS fit error, exposure→arrival latency with jitter, dropped frames,
//! missing tools, and the tip sphere only while it is attached.

use std::f64::consts::PI;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use sabr_recording::{Tool, ToolReading};

use crate::truth::ToolPoses;

/// Configuration of the tracker emulation. Ranges are sampled once per session.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerConfig {
    /// Nominal frame rate (Hz).
    pub rate_hz: f64,
    /// Frame-counter increment per delivered frame (1 on a Vicra).
    pub frame_increment: u32,
    /// RMS of the 3-D position noise of every tool (mm).
    pub position_noise_rms_mm: f64,
    /// Ratio of depth (z of `S`) to lateral noise standard deviation.
    pub depth_to_lateral: f64,
    /// RMS of the rotation noise angle (degrees).
    pub rotation_noise_rms_deg: f64,
    /// Range of the per-tool RMS fit error (mm), sampled per tool and session.
    pub fit_rms_mm: (f64, f64),
    /// Range of the exposure→arrival latency (ms), sampled once per session.
    pub latency_ms: (f64, f64),
    /// Standard deviation of the arrival jitter (ms), clipped at ±3σ.
    pub jitter_ms: f64,
    /// Probability that a frame arrives late (a host hiccup).
    pub late_probability: f64,
    /// Extra delay of a late frame, uniform in this range (ms).
    pub late_ms: (f64, f64),
    /// Probability that a frame never arrives (dropped).
    pub drop_probability: f64,
    /// Probability that a tool is missing in a frame.
    pub missing_probability: f64,
    /// Rate of occlusions per tool (per minute); each hides the tool for a while.
    pub occlusions_per_min: f64,
    /// Duration of an occlusion, uniform in this range (s).
    pub occlusion_s: (f64, f64),
    /// Maximum tracker clock rate error (ppm), sampled once per session (the `clockdrift`
    /// effect sets it exactly instead).
    pub clock_drift_ppm: f64,
    /// Range of the camera distance from the robot (mm).
    pub distance_mm: (f64, f64),
}

impl Default for TrackerConfig {
    /// A Polaris Vicra: 20 Hz, 0.25 mm RMS (depth 3× lateral), 0.1°, latency 20–60 ms.
    fn default() -> Self {
        TrackerConfig {
            rate_hz: 20.0,
            frame_increment: 1,
            position_noise_rms_mm: 0.25,
            depth_to_lateral: 3.0,
            rotation_noise_rms_deg: 0.1,
            fit_rms_mm: (0.08, 0.25),
            latency_ms: (20.0, 60.0),
            jitter_ms: 1.0,
            late_probability: 0.01,
            late_ms: (2.0, 15.0),
            drop_probability: 0.005,
            missing_probability: 0.003,
            occlusions_per_min: 0.5,
            occlusion_s: (0.2, 1.0),
            clock_drift_ppm: 50.0,
            distance_mm: (800.0, 1000.0),
        }
    }
}

/// The tracker's hidden truth for one session.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerTruth {
    /// `T_S_M`: the base marker in the tracker frame (mm).
    pub tracker_from_base: Isometry3<f64>,
    /// Session base latency exposure→arrival (ms), before injected extra latency.
    pub base_latency_ms: f64,
    /// Injected extra latency (ms), 0 without the latency effect.
    pub extra_latency_ms: f64,
    /// True frame period on the host clock (ns), including the tracker clock error.
    pub period_ns: f64,
    /// First exposure (robot time: ns after power-up).
    pub first_exposure_ns: i64,
    /// Frame counter of the first exposure.
    pub first_frame: u32,
    /// Frame-counter increment per frame.
    pub frame_increment: u32,
    /// Mean RMS fit error of the base, front and back tools (mm).
    pub fit_rms_mm: [f64; 3],
}

impl TrackerTruth {
    /// Samples a session: tracker `distance_mm` from `workspace_centre` (a point in `M`, mm), looking at
    /// it from 20–50° elevation, latency, clock error, frame counter start, fit errors.
    /// `exact_clock_drift_ppm` (the `clockdrift` effect) replaces the sampled clock rate error
    /// (ppm); the random draws stay the same, so nothing else changes.
    pub fn sample(
        config: &TrackerConfig,
        workspace_centre: &Point3<f64>,
        extra_latency_ms: f64,
        exact_clock_drift_ppm: Option<f64>,
        rng: &mut impl Rng,
    ) -> Self {
        let elevation = rng.random_range(20f64.to_radians()..=50f64.to_radians());
        let azimuth = rng.random_range(0.0..2.0 * PI);
        let roll = rng.random_range(-15f64.to_radians()..=15f64.to_radians());
        let distance = rng.random_range(config.distance_mm.0..=config.distance_mm.1);
        // z of S points from the robot to the camera: the robot is at negative depth.
        let z = Vector3::new(
            elevation.cos() * azimuth.cos(),
            elevation.cos() * azimuth.sin(),
            elevation.sin(),
        );
        let x = Vector3::z().cross(&z).normalize();
        let y = z.cross(&x);
        let rotation = UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_unchecked(z), roll)
            * UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_basis_unchecked(&[
                x, y, z,
            ]));
        let lateral = Vector3::new(
            rng.random_range(-100.0..=100.0),
            rng.random_range(-100.0..=100.0),
            0.0,
        );
        let camera = workspace_centre.coords + distance * z + rotation * lateral;
        let base_from_tracker = Isometry3::from_parts(Translation3::from(camera), rotation);

        let sampled_ppm = rng.random_range(-1.0..=1.0) * config.clock_drift_ppm;
        let drift = exact_clock_drift_ppm.unwrap_or(sampled_ppm) * 1e-6;
        let period_ns = 1e9 / config.rate_hz * (1.0 + drift);
        let first_exposure_ns = (rng.random_range(0.0..1.0) * period_ns) as i64;
        let (low, high) = config.fit_rms_mm;
        TrackerTruth {
            tracker_from_base: base_from_tracker.inverse(),
            base_latency_ms: rng.random_range(config.latency_ms.0..=config.latency_ms.1),
            extra_latency_ms,
            period_ns,
            first_exposure_ns,
            first_frame: rng.random_range(100..100_000),
            frame_increment: config.frame_increment,
            fit_rms_mm: std::array::from_fn(|_| rng.random_range(low..=high)),
        }
    }

    /// Total mean exposure→arrival latency (ms).
    pub fn latency_ms(&self) -> f64 {
        self.base_latency_ms + self.extra_latency_ms
    }
}

/// A tracker exposure: frame counter and instant (robot time, ns).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Exposure {
    /// Frame counter.
    pub frame: u32,
    /// Exposure instant (ns after power-up).
    pub exposure_ns: i64,
}

/// One tracker frame as the host receives it.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerFrame {
    /// The exposure.
    pub exposure: Exposure,
    /// When the frame becomes available to the host (ns after power-up): the latency and jitter
    /// run from the exposure to here. The rig's simulated device answers polls with the frame
    /// from this instant; an offline session records it with this stamp. `None` if the frame
    /// was dropped.
    pub arrival_ns: Option<i64>,
    /// Readings of base, front, back and tip, in `S`.
    pub readings: [(Tool, ToolReading); 4],
}

/// Gap (ns) kept between consecutive arrivals: frames arrive in order.
const MIN_ARRIVAL_GAP_NS: i64 = 1_000_000;
/// Relative spread of the per-frame fit error around the tool's mean.
const FIT_RMS_SPREAD: f64 = 0.1;

/// Produces tracker frames one exposure at a time.
#[derive(Debug, Clone)]
pub struct TrackerEmulator {
    config: TrackerConfig,
    truth: TrackerTruth,
    base_to_robot: Isometry3<f64>,
    rng: ChaCha8Rng,
    index: u64,
    last_arrival_ns: i64,
    occluded_until_ns: [i64; 4],
}

impl TrackerEmulator {
    /// An emulator for `truth`; `base_to_robot` is the true `T_M_Bb`.
    pub fn new(
        config: TrackerConfig,
        truth: TrackerTruth,
        base_to_robot: Isometry3<f64>,
        rng: ChaCha8Rng,
    ) -> Self {
        TrackerEmulator {
            config,
            truth,
            base_to_robot,
            rng,
            index: 0,
            last_arrival_ns: i64::MIN / 2,
            occluded_until_ns: [i64::MIN; 4],
        }
    }

    /// The session truth.
    pub fn truth(&self) -> &TrackerTruth {
        &self.truth
    }

    /// The next exposure (not yet captured).
    pub fn next_exposure(&self) -> Exposure {
        let truth = &self.truth;
        Exposure {
            frame: truth
                .first_frame
                .wrapping_add((self.index as u32).wrapping_mul(truth.frame_increment)),
            exposure_ns: truth.first_exposure_ns
                + (self.index as f64 * truth.period_ns).round() as i64,
        }
    }

    fn normal(&mut self) -> f64 {
        self.rng.sample(StandardNormal)
    }

    fn position_noise(&mut self) -> Vector3<f64> {
        let ratio = self.config.depth_to_lateral;
        let lateral = self.config.position_noise_rms_mm / (2.0 + ratio * ratio).sqrt();
        Vector3::new(
            lateral * self.normal(),
            lateral * self.normal(),
            ratio * lateral * self.normal(),
        )
    }

    fn pose_reading(&mut self, tool: usize, pose: &Isometry3<f64>) -> ToolReading {
        let position = pose.translation.vector + self.position_noise();
        let sigma = self.config.rotation_noise_rms_deg.to_radians() / 3f64.sqrt();
        let omega = Vector3::new(self.normal(), self.normal(), self.normal()) * sigma;
        let mut rotation = (UnitQuaternion::from_scaled_axis(omega) * pose.rotation).into_inner();
        if rotation.w < 0.0 {
            rotation = -rotation;
        }
        let rms = self.truth.fit_rms_mm[tool] * (1.0 + FIT_RMS_SPREAD * self.normal()).max(0.1);
        ToolReading::Pose {
            quaternion: [rotation.w, rotation.i, rotation.j, rotation.k],
            position: [position.x, position.y, position.z],
            rms,
        }
    }

    /// Whether tool `index` is hidden at `t_ns` (occlusions and random misses).
    fn hidden(&mut self, index: usize, t_ns: i64) -> bool {
        let period_s = self.truth.period_ns * 1e-9;
        let start_probability = (self.config.occlusions_per_min / 60.0 * period_s).min(1.0);
        if self.rng.random_bool(start_probability) {
            let (low, high) = self.config.occlusion_s;
            let length_s = self.rng.random_range(low..=high);
            self.occluded_until_ns[index] = t_ns + (length_s * 1e9) as i64;
        }
        let missed = self.rng.random_bool(self.config.missing_probability);
        missed || t_ns < self.occluded_until_ns[index]
    }

    fn arrival(&mut self, exposure_ns: i64) -> Option<i64> {
        let jitter_ms = self.config.jitter_ms * self.normal().clamp(-3.0, 3.0);
        let late_ms = if self.rng.random_bool(self.config.late_probability) {
            self.rng
                .random_range(self.config.late_ms.0..=self.config.late_ms.1)
        } else {
            0.0
        };
        if self.rng.random_bool(self.config.drop_probability) {
            return None;
        }
        let delay_ms = self.truth.latency_ms() + jitter_ms + late_ms;
        let arrival = (exposure_ns + (delay_ms * 1e6).round() as i64)
            .max(self.last_arrival_ns + MIN_ARRIVAL_GAP_NS);
        self.last_arrival_ns = arrival;
        Some(arrival)
    }

    /// Captures the next exposure of the true scene `tools` (in `Bb`); the tip sphere is seen
    /// only if `tip_attached`.
    pub fn capture(&mut self, tools: &ToolPoses, tip_attached: bool) -> TrackerFrame {
        let exposure = self.next_exposure();
        self.index += 1;
        let t = exposure.exposure_ns;
        let tracker_from_robot = self.truth.tracker_from_base * self.base_to_robot;
        let truths = [
            self.truth.tracker_from_base,
            tracker_from_robot * tools.front,
            tracker_from_robot * tools.back,
        ];
        let tools_in_order = [Tool::Base, Tool::Front, Tool::Back];
        let mut readings = [(Tool::Tip, ToolReading::Missing); 4];
        for (index, (tool, pose)) in tools_in_order.iter().zip(truths.iter()).enumerate() {
            let reading = self.pose_reading(index, pose);
            let hidden = self.hidden(index, t);
            readings[index] = (
                *tool,
                if hidden {
                    ToolReading::Missing
                } else {
                    reading
                },
            );
        }
        let tip = tracker_from_robot * tools.tip + self.position_noise();
        let tip_hidden = self.hidden(3, t);
        if tip_attached && !tip_hidden {
            readings[3].1 = ToolReading::Point {
                position: [tip.x, tip.y, tip.z],
                rms: 0.0,
            };
        }
        TrackerFrame {
            exposure,
            arrival_ns: self.arrival(t),
            readings,
        }
    }
}
