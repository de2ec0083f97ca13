//! The true robot: parameters perturbed from nominal (seeded), its mechanical stops, the
//! power-up pose, and [`TrueRobot`], which turns motor setpoints into true joint angles and
//! poses. It knows nothing about how it is driven (offline plan or real-time rig).

use std::borrow::Cow;
use std::f64::consts::PI;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sabr_model::effects::{apply_joint_effects, EncoderScale, JointMotion};
use sabr_model::plan::{SessionPlan, EXCITATION_AMPLITUDE};
use sabr_model::realtime::RealtimeGeometry;
use sabr_model::Effect;
use sabr_model::{
    forward, inverse, Counts, Geometry, Joints, KinematicsError, NeedlePose, RobotParams,
};

use crate::effect_spec::SimEffect;
use crate::SimError;

/// Attempts at drawing a robot whose nominal tip error is in the wanted range.
const MAX_ATTEMPTS: usize = 1000;
/// Number of reference poses over which the nominal tip error is evaluated.
const REFERENCE_POSES: usize = 25;
/// Seed of the fixed reference poses (the same for every session).
const REFERENCE_SEED: u64 = 0x5AB2;

/// Half-widths of the uniform perturbations of the true robot from nominal.
#[derive(Debug, Clone, PartialEq)]
pub struct Perturbation {
    /// Relative gear-ratio error (0.03 = ±3 %).
    pub gear_ratio_rel: f64,
    /// Mechanical stop error (rad).
    pub stop_rad: f64,
    /// Front-base translation error per axis (mm).
    pub front_base_translation_mm: f64,
    /// Front-base tilt about x and y of `Bb` (rad); no rotation about z.
    pub front_base_tilt_rad: f64,
    /// Needle length error (mm).
    pub needle_length_mm: f64,
    /// Marker mounting translation error per axis (mm).
    pub mount_translation_mm: f64,
    /// Marker mounting rotation error per rotation-vector component (rad).
    pub mount_rotation_rad: f64,
    /// Spread of the power-up pose around the excitation centre (rad).
    pub power_up_rad: f64,
    /// If set, robots are drawn until the nominal model with homing offsets has an RMS tip
    /// error in this range (mm) over reference poses of the excitation envelope.
    pub nominal_tip_rms_mm: Option<(f64, f64)>,
}

impl Default for Perturbation {
    /// The default amounts: gear ratios ±3 %, stops ±2°, front base ±1.5 mm / ±0.6°,
    /// needle ±3 mm, mountings ±1 mm / ±2°; nominal tip error 3–6 mm RMS as in the paper.
    fn default() -> Self {
        Perturbation {
            gear_ratio_rel: 0.03,
            stop_rad: 2f64.to_radians(),
            front_base_translation_mm: 1.5,
            front_base_tilt_rad: 0.6f64.to_radians(),
            needle_length_mm: 3.0,
            mount_translation_mm: 1.0,
            mount_rotation_rad: 2f64.to_radians(),
            power_up_rad: 0.12,
            nominal_tip_rms_mm: Some((3.0, 6.0)),
        }
    }
}

/// A thermal drift of one joint offset (simulator-only effect).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThermalDrift {
    /// Joint index 0..5.
    pub joint: usize,
    /// Final drift (rad).
    pub amplitude: f64,
    /// Time constant (s).
    pub tau_s: f64,
}

impl ThermalDrift {
    /// The thermal drifts among the injected `effects`, in their order.
    pub fn all_in(effects: &[SimEffect]) -> Vec<ThermalDrift> {
        effects
            .iter()
            .filter_map(|e| match *e {
                SimEffect::Thermal {
                    joint,
                    amplitude,
                    tau_s,
                } => Some(ThermalDrift {
                    joint,
                    amplitude,
                    tau_s,
                }),
                _ => None,
            })
            .collect()
    }

    /// Drift (rad) at `t_ns` after power-up.
    pub fn drift_at(&self, t_ns: i64) -> f64 {
        self.amplitude * (1.0 - (-(t_ns as f64) * 1e-9 / self.tau_s).exp())
    }
}

/// A thermal drift of one link length (simulator-only effect).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkDrift {
    /// The link whose length drifts.
    pub link: sabr_model::Link,
    /// Final length change (mm).
    pub delta: f64,
    /// Time constant (s).
    pub tau_s: f64,
}

impl LinkDrift {
    /// The link drifts among the injected `effects`, in their order.
    pub fn all_in(effects: &[SimEffect]) -> Vec<LinkDrift> {
        effects
            .iter()
            .filter_map(|e| match *e {
                SimEffect::LinkThermal { link, delta, tau_s } => {
                    Some(LinkDrift { link, delta, tau_s })
                }
                _ => None,
            })
            .collect()
    }

    /// Length change (mm) at `t_ns` after power-up: `delta · (1 − exp(−t / tau_s))`.
    pub fn drift_at(&self, t_ns: i64) -> f64 {
        self.delta * (1.0 - (-(t_ns as f64) * 1e-9 / self.tau_s).exp())
    }

    /// Adds the drift at `t_ns` to the drifting link of `geometry` (mm).
    pub fn apply(&self, geometry: &mut Geometry, t_ns: i64) {
        use sabr_model::Link;
        let length = match self.link {
            Link::LF => &mut geometry.l_f,
            Link::LFe => &mut geometry.l_fe,
            Link::LB => &mut geometry.l_b,
            Link::LBe => &mut geometry.l_be,
            Link::DOffset => &mut geometry.d_offset,
        };
        *length += self.drift_at(t_ns);
    }
}

/// Gravity direction in `Bb` (unit): −y.
const GRAVITY_IN_BB: Vector3<f64> = Vector3::new(0.0, -1.0, 0.0);

/// Deflection (mm, in `Bb`) of the needle tip by a sag of `mm` under gravity: the component of
/// gravity (−y of `Bb`) perpendicular to the needle direction `z_N` (unit), times `mm`, i.e.
/// `mm · (g − z_N (g·z_N))`; `mm` long when the needle is horizontal, zero when vertical.
pub fn sag_deflection(mm: f64, direction: &Vector3<f64>) -> Vector3<f64> {
    mm * (GRAVITY_IN_BB - direction * GRAVITY_IN_BB.dot(direction))
}

/// The needle sag (mm of a horizontal needle) of the injected `effects`, 0 without one.
pub(crate) fn needle_sag_mm(effects: &[SimEffect]) -> f64 {
    effects
        .iter()
        .filter_map(|e| match *e {
            SimEffect::NeedleSag { mm } => Some(mm),
            _ => None,
        })
        .sum()
}

/// Everything about the true robot: true parameters (with the true offsets and the injected
/// model effects), stops, power-up pose, simulator-only effects.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotTruth {
    /// True parameters. `joints.offset` is `Some(power-up joints)` since counts are zero
    /// there; `effects` holds the injected model effects.
    pub params: RobotParams,
    /// True mechanical stops, paper joint angles `GR·θ_enc + θ_off` (rad).
    pub stops: Joints,
    /// Side of each stop: +1 if the stop bounds the joint from above, −1 from below.
    pub stop_side: [f64; 5],
    /// True joint angles at power-up (rad).
    pub power_up_joints: Joints,
    /// Simulator-only joint drifts.
    pub thermal: Vec<ThermalDrift>,
    /// Simulator-only link-length drifts, added to the effective geometry.
    pub link_drift: Vec<LinkDrift>,
    /// Simulator-only needle sag under gravity (mm of a horizontal needle; 0 = none).
    pub needle_sag_mm: f64,
}

/// Uniform sample in `[-half, half]`.
fn spread(rng: &mut impl Rng, half: f64) -> f64 {
    if half > 0.0 {
        rng.random_range(-half..=half)
    } else {
        0.0
    }
}

fn perturb_pose(rng: &mut impl Rng, pose: &Isometry3<f64>, mm: f64, rad: f64) -> Isometry3<f64> {
    let dt = Vector3::new(spread(rng, mm), spread(rng, mm), spread(rng, mm));
    let dr = Vector3::new(spread(rng, rad), spread(rng, rad), spread(rng, rad));
    Isometry3::from_parts(
        Translation3::from(pose.translation.vector + dt),
        pose.rotation * UnitQuaternion::from_scaled_axis(dr),
    )
}

/// The paper-model part of a true robot, before effects.
struct Draw {
    params: RobotParams,
    stops: Joints,
    power_up_joints: Joints,
}

fn draw(
    nominal: &RobotParams,
    amounts: &Perturbation,
    centre: &Joints,
    rng: &mut impl Rng,
) -> Draw {
    let mut params = nominal.clone();
    for ratio in params.joints.gear_ratio.iter_mut() {
        *ratio *= 1.0 + spread(rng, amounts.gear_ratio_rel);
    }
    let nominal_stops = nominal.joints.home_stops;
    let stops: Joints = std::array::from_fn(|i| nominal_stops[i] + spread(rng, amounts.stop_rad));

    let geometry = &mut params.geometry;
    let tilt = Vector3::new(
        spread(rng, amounts.front_base_tilt_rad),
        spread(rng, amounts.front_base_tilt_rad),
        0.0,
    );
    let shift = Vector3::from_fn(|_, _| spread(rng, amounts.front_base_translation_mm));
    geometry.front_base = Isometry3::from_parts(
        Translation3::from(geometry.front_base.translation.vector + shift),
        UnitQuaternion::from_scaled_axis(tilt) * geometry.front_base.rotation,
    );
    geometry.l_n += spread(rng, amounts.needle_length_mm);

    let markers = &mut params.markers;
    let (mm, rad) = (amounts.mount_translation_mm, amounts.mount_rotation_rad);
    markers.front_mount = perturb_pose(rng, &markers.front_mount, mm, rad);
    markers.back_mount = perturb_pose(rng, &markers.back_mount, mm, rad);

    let power_up_joints: Joints =
        std::array::from_fn(|i| centre[i] + spread(rng, amounts.power_up_rad));
    params.joints.offset = Some(power_up_joints);
    Draw {
        params,
        stops,
        power_up_joints,
    }
}

/// RMS tip error (mm) of the nominal model with homing offsets against the drawn robot, over
/// fixed reference poses of the excitation envelope; `None` if FK fails somewhere.
///
/// Homing reads the counts at the true stop, so the nominal model maps true paper joints `q`
/// to `stop_nom + GR_nom / GR_true · (q − stop_true)`.
fn nominal_tip_rms(nominal: &RobotParams, robot: &Draw, centre: &Joints) -> Option<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(REFERENCE_SEED);
    let reach = EXCITATION_AMPLITUDE;
    let ratio_nominal = &nominal.joints.gear_ratio;
    let ratio_true = &robot.params.joints.gear_ratio;
    let stops_nominal = &nominal.joints.home_stops;
    let mut sum = 0.0;
    for _ in 0..REFERENCE_POSES {
        let q: Joints = std::array::from_fn(|i| centre[i] + rng.random_range(-reach..=reach));
        let q_nominal: Joints = std::array::from_fn(|i| {
            stops_nominal[i] + ratio_nominal[i] / ratio_true[i] * (q[i] - robot.stops[i])
        });
        let truth = forward(&robot.params.geometry, &q).ok()?;
        let model = forward(&nominal.geometry, &q_nominal).ok()?;
        sum += (truth.tip - model.tip).norm_squared();
    }
    Some((sum / REFERENCE_POSES as f64).sqrt())
}

/// Sampling period of the reachability check (ns).
const CHECK_PERIOD_NS: i64 = 50_000_000;
/// Joint tolerance of the IK round trip in the reachability check (rad).
const IK_TOLERANCE: f64 = 1e-6;

impl RobotTruth {
    /// Checks that the true robot following `plan` stays in its reachable workspace: at
    /// every 50 ms, FK of the true joints (geometry at that time, needle rigid) exists and
    /// IK recovers them.
    pub fn check_reachable(&self, plan: &SessionPlan) -> Result<(), SimError> {
        let mut robot = TrueRobot::new(self.clone());
        let mut t_ns = 0;
        while t_ns <= plan.end_ns() {
            robot.command(t_ns, &self.motor_for_joints(&plan.joints_at(t_ns)));
            let q = robot.joints();
            let unreachable = |reason: String| SimError::Unreachable {
                t_s: t_ns as f64 * 1e-9,
                joints: q,
                reason,
            };
            let pose = robot.rigid_pose().map_err(|e| unreachable(e.to_string()))?;
            let back = inverse(&robot.geometry(), &pose.tip, &pose.direction, &q)
                .map_err(|e| unreachable(format!("IK of the FK pose fails: {e}")))?;
            let error = q
                .iter()
                .zip(&back)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            if error > IK_TOLERANCE {
                return Err(unreachable(format!(
                    "IK recovers the joints only to {error:.2e} rad (near a singularity)"
                )));
            }
            t_ns += CHECK_PERIOD_NS;
        }
        Ok(())
    }

    /// Samples a true robot around `nominal`: perturbed gear ratios, stops, front base,
    /// needle length and mountings; a power-up pose near `centre` (rad); `effects` injected.
    /// `T_M_Bb` stays nominal (it is known from the base fixture). With
    /// `amounts.nominal_tip_rms_mm` set, draws again until the nominal model's tip error is
    /// in range (effects do not take part, so they do not change the drawn robot).
    pub fn sample(
        nominal: &RobotParams,
        amounts: &Perturbation,
        centre: &Joints,
        effects: &[SimEffect],
        rng: &mut impl Rng,
    ) -> Result<Self, SimError> {
        let mut robot = draw(nominal, amounts, centre, rng);
        if let Some((low, high)) = amounts.nominal_tip_rms_mm {
            let mut attempts = 1;
            while !nominal_tip_rms(nominal, &robot, centre).is_some_and(|e| low <= e && e <= high) {
                if attempts == MAX_ATTEMPTS {
                    return Err(SimError::Config(format!(
                        "no robot drawn in {MAX_ATTEMPTS} attempts has a nominal tip error in \
                         [{low}, {high}] mm: the perturbation amounts do not fit that range"
                    )));
                }
                robot = draw(nominal, amounts, centre, rng);
                attempts += 1;
            }
        }
        let Draw {
            mut params,
            stops,
            power_up_joints,
        } = robot;
        params.effects = effects
            .iter()
            .filter_map(|e| e.model_effect().cloned())
            .collect();
        let thermal = ThermalDrift::all_in(effects);
        let nominal_stops = nominal.joints.home_stops;
        Ok(RobotTruth {
            params,
            stops,
            stop_side: std::array::from_fn(|i| (nominal_stops[i] - centre[i]).signum()),
            power_up_joints,
            thermal,
            link_drift: LinkDrift::all_in(effects),
            needle_sag_mm: needle_sag_mm(effects),
        })
    }

    /// True offsets θ_off (rad): the power-up joints, since counts are zero there.
    pub fn offsets(&self) -> Joints {
        self.power_up_joints
    }

    /// Motor angles θ_enc (rad) that put the paper joints `GR·θ_enc + θ_off` at `q` (rad).
    pub fn motor_for_joints(&self, q: &Joints) -> Joints {
        let ratio = &self.params.joints.gear_ratio;
        let offset = self.offsets();
        std::array::from_fn(|i| (q[i] - offset[i]) / ratio[i])
    }

    /// Paper joints `GR·θ_enc + θ_off` (rad) of motor angles `motor` (rad).
    pub fn paper_joints(&self, motor: &Joints) -> Joints {
        let ratio = &self.params.joints.gear_ratio;
        let offset = self.offsets();
        std::array::from_fn(|i| ratio[i] * motor[i] + offset[i])
    }
}

/// Encoder counts of motor angles (rad): `round(θ_enc · cpr / 2π)`, zero at power-up.
pub fn quantise_counts(motor: &Joints, counts_per_rev: &[u32; 5]) -> Counts {
    std::array::from_fn(|i| (motor[i] * f64::from(counts_per_rev[i]) / (2.0 * PI)).round() as i64)
}

/// The true robot in operation: motor setpoints in, true motor angles, counts, joints and
/// poses out. Times are robot time (ns since power-up).
#[derive(Debug, Clone)]
pub struct TrueRobot {
    truth: RobotTruth,
    geometry: Geometry,
    /// `geometry` prepared for the real-time kinematics of every tick.
    realtime: RealtimeGeometry,
    motor: Joints,
    t_ns: i64,
    /// The injected joint-side effects other than backlash.
    smooth_effects: Vec<Effect>,
    scale: EncoderScale,
    /// Half the backlash width of each joint (rad, 0 without backlash).
    play_half_width: Joints,
    /// The play operator's output per joint: the paper joint angle the gap lets through
    /// (rad), carried through time.
    play_output: Joints,
}

/// True tool poses in `Bb` at one instant.
#[derive(Debug, Clone, PartialEq)]
pub struct ToolPoses {
    /// `T_Bb_Tf`: front marker tool.
    pub front: Isometry3<f64>,
    /// `T_Bb_Tb`: back marker tool.
    pub back: Isometry3<f64>,
    /// Needle tip `p_n` (mm).
    pub tip: Point3<f64>,
}

impl TrueRobot {
    /// The robot at power-up: motor angles and counts zero, at its power-up pose.
    /// Each joint's backlash is a play operator whose gap is centred at power-up.
    pub fn new(truth: RobotTruth) -> Self {
        let geometry = truth.params.effective_geometry();
        let mut play_half_width = [0.0; 5];
        let mut smooth_effects = Vec::new();
        for effect in &truth.params.effects {
            match *effect {
                Effect::Backlash { joint, width } if joint < 5 => {
                    play_half_width[joint] += 0.5 * width;
                }
                _ => smooth_effects.push(effect.clone()),
            }
        }
        let motor = [0.0; 5];
        TrueRobot {
            play_output: truth.paper_joints(&motor),
            scale: truth.params.encoder_scale(),
            truth,
            realtime: RealtimeGeometry::from(&geometry),
            geometry,
            motor,
            t_ns: 0,
            smooth_effects,
            play_half_width,
        }
    }

    /// The truth this robot was built from.
    pub fn truth(&self) -> &RobotTruth {
        &self.truth
    }

    /// Drives the motors to `setpoint` (rad) at `t_ns`. The motors follow exactly, except
    /// that a joint pushed into its mechanical stop stays there (so does its motor).
    pub fn command(&mut self, t_ns: i64, setpoint: &Joints) {
        let truth = &self.truth;
        let q = truth.paper_joints(setpoint);
        let stop_motor = truth.motor_for_joints(&truth.stops);
        for i in 0..5 {
            let target = if truth.stop_side[i] * (q[i] - truth.stops[i]) > 0.0 {
                stop_motor[i]
            } else {
                setpoint[i]
            };
            self.motor[i] = target;
        }
        // The motors move monotonically between commands, so clamping at the end of the
        // step is the play operator along it.
        let x = self.truth.paper_joints(&self.motor);
        for (i, h) in self.play_half_width.iter().enumerate() {
            self.play_output[i] = self.play_output[i].clamp(x[i] - h, x[i] + h);
        }
        self.t_ns = t_ns;
    }

    /// Robot time (ns since power-up) of the last command.
    pub fn time_ns(&self) -> i64 {
        self.t_ns
    }

    /// True motor angles θ_enc (rad), zero at power-up.
    pub fn motor_angles(&self) -> Joints {
        self.motor
    }

    /// Encoder counts of the current motor angles.
    pub fn counts(&self) -> Counts {
        quantise_counts(&self.motor, &self.truth.params.joints.counts_per_rev)
    }

    /// Paper joints `GR·θ_enc + θ_off` (rad), before any effect.
    pub fn paper_joints(&self) -> Joints {
        self.truth.paper_joints(&self.motor)
    }

    /// True joint angles (rad): paper joints plus the injected joint-side effects (ripple
    /// and compliance as `sabr_model::effects` defines them, backlash as the play operator
    /// run through every commanded step, then thermal drift).
    pub fn joints(&self) -> Joints {
        let paper = self.paper_joints();
        let mut q = apply_joint_effects(
            &self.smooth_effects,
            &paper,
            &self.motor,
            &self.scale,
            &JointMotion::default(),
        );
        for i in 0..5 {
            q[i] += self.play_output[i] - paper[i];
        }
        for drift in &self.truth.thermal {
            q[drift.joint] += drift.drift_at(self.t_ns);
        }
        q
    }

    /// True needle and effector poses in `Bb` (FK of the true joints, true geometry with
    /// link-length effects and link drifts at the current time), the needle tip deflected by
    /// its sag: the tip and the origin of `T_Bb_N` move, the direction and effectors do not.
    pub fn pose(&self) -> Result<NeedlePose, KinematicsError> {
        let mut pose = self.rigid_pose()?;
        if self.truth.needle_sag_mm > 0.0 {
            let deflection = sag_deflection(self.truth.needle_sag_mm, &pose.direction);
            pose.tip += deflection;
            pose.needle.translation.vector += deflection;
        }
        Ok(pose)
    }

    /// Needle and effector poses in `Bb` of a rigid needle (no sag): FK of the true joints
    /// with the true geometry at the current time (the real-time kinematics; a geometry with
    /// link drifts is prepared anew at each call).
    pub fn rigid_pose(&self) -> Result<NeedlePose, KinematicsError> {
        let joints = self.joints();
        let pose = match self.geometry() {
            Cow::Borrowed(_) => self.realtime.forward(&joints)?,
            Cow::Owned(drifted) => RealtimeGeometry::from(&drifted).forward(&joints)?,
        };
        Ok(pose.to_nalgebra())
    }

    /// True geometry at the current time (mm): the truth's effective geometry (link-length
    /// effects) plus the link drifts at the time of the last command.
    pub fn geometry(&self) -> Cow<'_, Geometry> {
        if self.truth.link_drift.is_empty() {
            return Cow::Borrowed(&self.geometry);
        }
        let mut geometry = self.geometry.clone();
        for drift in &self.truth.link_drift {
            drift.apply(&mut geometry, self.t_ns);
        }
        Cow::Owned(geometry)
    }

    /// True tool poses in `Bb`: effector poses times the true marker mountings, and the tip
    /// of [`TrueRobot::pose`] (with its sag).
    pub fn tool_poses(&self) -> Result<ToolPoses, KinematicsError> {
        let pose = self.pose()?;
        let markers = &self.truth.params.markers;
        Ok(ToolPoses {
            front: pose.front_effector * markers.front_mount,
            back: pose.back_effector * markers.back_mount,
            tip: pose.tip,
        })
    }
}
