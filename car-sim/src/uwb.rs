//! UWB (`docs/firmware.md#uwb-positioning`): the firmware's anchor list and round-robin scheduler,
//! the radio model of a DS-TWR exchange against the world, and the UWB position estimator of both
//! firmware eras.

use scenarios::geometry::Point;

use crate::autopilot::FwPose;
use crate::noise::Noise;
use crate::positioning::wrap180;
use crate::world::{RadioPath, World};
use car_link::firmware::{
    AnchorAdd, FirmwareProfile, FirmwareVersion, UwbEstimator as Estimator, UwbReset,
};

/// Most anchors the firmware stores.
pub use car_link::firmware::MAX_ANCHORS;
/// Anchors further than this from the UWB estimate are not ranged, m.
pub const RANGING_GATE_M: f32 = 80.0;
/// Distance of the UWB antenna ahead of the reference point, m.
pub const ANTENNA_OFFSET_M: f32 = 0.085;
/// Exchanges averaged per range request.
pub const EXCHANGES: usize = 5;
/// 10.x: ranges shorter than predicted by this much or more are ignored, m.
const GATE_10X_M: f32 = 8.0;
/// Largest correction per range, m: a compile-time constant of the firmware (both eras), the
/// method's "correction clamp". A simulation may change it ([`UwbEstimator::set_step_clamp`]).
pub const MAX_STEP_M: f32 = car_link::firmware::UWB_CORRECTION_CLAMP_M as f32;
/// 12.x yaw history length.
const YAW_HISTORY: usize = 50;
/// 12.x stationary clamp speed: 0.5 km/h in m/s.
const CLAMP_SPEED: f32 = 0.5 / 3.6;

/// An anchor in the firmware's list.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FwAnchor {
    /// Anchor id (the module is addressed with its low byte).
    pub id: i16,
    /// East, m.
    pub px: f32,
    /// North, m.
    pub py: f32,
    /// Height, m (stored, never used).
    pub height: f32,
    /// The last range stored for it, m.
    pub dist_last: f32,
    /// When that range arrived (simulation ms).
    pub last_ms: Option<u64>,
}

/// The radio model of the simulated UWB module and anchors (not firmware behaviour: physics).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadioModel {
    /// Standard deviation of one two-way exchange at line of sight, m.
    pub exchange_sigma_m: f64,
    /// Extra standard deviation of an exchange over a reflected path, m.
    pub nlos_extra_sigma_m: f64,
    /// Probability that one exchange fails (then the whole request returns nothing).
    pub exchange_drop_probability: f64,
    /// Each physical anchor has a constant range bias (antenna-delay calibration error) drawn
    /// uniformly from this interval, m.
    pub anchor_bias_m: (f64, f64),
    /// Which bias each anchor id has: a property of the hardware, so it stays the same whatever
    /// the simulation's seed (which draws the noise): runs with other seeds are the same car and
    /// anchors with other noise.
    pub anchor_bias_seed: u64,
    /// Height of the car's UWB antenna above ground, m.
    pub antenna_height_m: f64,
    /// Beyond this slant range no exchange succeeds, m.
    pub max_range_m: f64,
}

impl Default for RadioModel {
    fn default() -> Self {
        Self {
            exchange_sigma_m: 0.10,
            nlos_extra_sigma_m: 0.10,
            exchange_drop_probability: 0.002,
            anchor_bias_m: (0.0, 0.25),
            anchor_bias_seed: 0,
            antenna_height_m: 1.0,
            max_range_m: 150.0,
        }
    }
}

impl RadioModel {
    /// The range bias of the anchor at `address` when nothing says otherwise: drawn uniformly
    /// from [`RadioModel::anchor_bias_m`] by the address and [`RadioModel::anchor_bias_seed`].
    pub fn drawn_bias(&self, address: u8) -> f64 {
        Noise::stream(self.anchor_bias_seed, 0x0A0C_0000 + u64::from(address))
            .uniform_in(self.anchor_bias_m.0, self.anchor_bias_m.1)
    }
}

/// How one range request went.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RangeResult {
    /// The module returned a range (mean of the exchanges, whole millimetres), m.
    Measured(f32),
    /// The path was blocked and no wall reflected: nothing returned.
    Blocked,
    /// An exchange failed (noise, out of radio range): nothing returned.
    Dropped,
    /// No anchor answers to that address.
    NoResponder,
}

/// One range request as the physics saw it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeMeasurement {
    /// The address the request went to (the anchor id's low byte).
    pub address: u8,
    /// The radio path taken, when an anchor answers.
    pub path: Option<RadioPath>,
    /// The true slant range along the direct path, m.
    pub true_range: Option<f64>,
    /// What the module returned.
    pub result: RangeResult,
}

/// Where a physical anchor is and its bias.
struct Responder {
    position: Point,
    height: f64,
    bias: f64,
}

/// Measures one range request from the car's antenna to the anchor at `address`.
pub fn measure_range(
    world: &World,
    fallback: Option<&FwAnchor>,
    address: u8,
    antenna: Point,
    radio: &RadioModel,
    noise: &mut Noise,
) -> RangeMeasurement {
    let Some(responder) = responder(world, fallback, address, radio) else {
        return RangeMeasurement {
            address,
            path: None,
            true_range: None,
            result: RangeResult::NoResponder,
        };
    };
    let dz = responder.height - radio.antenna_height_m;
    let slant = |planar: f64| planar.hypot(dz);
    let path = world.radio_path(antenna, responder.position);
    let true_range = Some(slant(antenna.dist(responder.position)));
    let result = match path {
        RadioPath::Blocked => RangeResult::Blocked,
        _ => exchanges(path, slant, responder.bias, radio, noise),
    };
    RangeMeasurement {
        address,
        path: Some(path),
        true_range,
        result,
    }
}

fn responder(
    world: &World,
    fallback: Option<&FwAnchor>,
    address: u8,
    radio: &RadioModel,
) -> Option<Responder> {
    let bias = radio.drawn_bias(address);
    if let Some(a) = world.anchor(address) {
        return Some(Responder {
            position: a.position,
            height: a.height,
            bias: a.range_bias_m.unwrap_or(bias),
        });
    }
    // No physical anchor with that id in the world: the uploaded entry is taken as the truth.
    let f = fallback?;
    Some(Responder {
        position: Point::new(f64::from(f.px), f64::from(f.py)),
        height: f64::from(f.height),
        bias,
    })
}

fn exchanges(
    path: RadioPath,
    slant: impl Fn(f64) -> f64,
    bias: f64,
    radio: &RadioModel,
    noise: &mut Noise,
) -> RangeResult {
    let Some(planar) = path.length() else {
        return RangeResult::Blocked;
    };
    let range = slant(planar);
    if range > radio.max_range_m {
        return RangeResult::Dropped;
    }
    let sigma = match path {
        RadioPath::Reflected { .. } => radio.exchange_sigma_m.hypot(radio.nlos_extra_sigma_m),
        _ => radio.exchange_sigma_m,
    };
    let mut sum = 0.0;
    for _ in 0..EXCHANGES {
        if noise.chance(radio.exchange_drop_probability) {
            return RangeResult::Dropped;
        }
        sum += range + bias + noise.gaussian(sigma);
    }
    let mm = (sum / EXCHANGES as f64 * 1000.0).trunc();
    RangeResult::Measured((mm / 1000.0) as f32)
}

/// The firmware's anchor list and its round-robin scheduler.
#[derive(Debug, Clone, PartialEq)]
pub struct AnchorList {
    firmware: FirmwareProfile,
    anchors: Vec<FwAnchor>,
    last_used: usize,
}

/// What the scheduler decided this round.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Schedule {
    /// Range to the anchor at this list index.
    Range(usize),
    /// No anchor qualifies (one anchor only, or none within the gate).
    Idle,
    /// The firmware would spin forever here (the anchor-walk hang,
    /// `docs/firmware.md#ranging-schedule`: the list shrank below `last_used`); the simulator skips
    /// the round instead.
    WalkWouldHang,
}

impl AnchorList {
    /// An empty list (as after boot).
    pub fn new(firmware: FirmwareVersion) -> Self {
        Self {
            firmware: firmware.profile(),
            anchors: Vec::new(),
            last_used: 0,
        }
    }

    /// The anchors.
    pub fn anchors(&self) -> &[FwAnchor] {
        &self.anchors
    }

    /// ADD_UWB_ANCHOR: 10.x appends duplicates, 12.x updates an existing id; beyond 20 anchors
    /// the add is ignored.
    pub fn add(&mut self, id: i16, px: f32, py: f32, height: f32) {
        if self.firmware.anchor_add == AnchorAdd::UpdateExisting
            && let Some(a) = self.anchors.iter_mut().find(|a| a.id == id)
        {
            a.px = px;
            a.py = py;
            a.height = height;
            return;
        }
        if self.anchors.len() < MAX_ANCHORS {
            self.anchors.push(FwAnchor {
                id,
                px,
                py,
                height,
                dist_last: 0.0,
                last_ms: None,
            });
        }
    }

    /// CLEAR_UWB_ANCHORS: the count goes to 0 (`last_used` is kept, as in the firmware).
    pub fn clear(&mut self) {
        self.anchors.clear();
    }

    /// The first anchor whose id equals the reply's address.
    pub fn find_mut(&mut self, address: u8) -> Option<&mut FwAnchor> {
        self.anchors.iter_mut().find(|a| a.id == i16::from(address))
    }

    /// The first anchor whose id equals `address` (for the fallback responder).
    pub fn find(&self, address: u8) -> Option<&FwAnchor> {
        self.anchors.iter().find(|a| a.id == i16::from(address))
    }

    /// One 100 ms scheduling round: walk from `last_used + 1`, wrapping, up to (excluding)
    /// `last_used`, and pick the first anchor within 80 m of the UWB estimate.
    pub fn schedule(&mut self, estimate: (f32, f32)) -> Schedule {
        let count = self.anchors.len();
        if count == 0 {
            return Schedule::Idle;
        }
        let within = |a: &FwAnchor| (a.px - estimate.0).hypot(a.py - estimate.1) < RANGING_GATE_M;
        if self.last_used >= count {
            // The firmware's walk never returns to last_used: it ends only at a passing anchor.
            return match (0..count).find(|&i| within(&self.anchors[i])) {
                Some(i) => {
                    self.last_used = i;
                    Schedule::Range(i)
                }
                None => Schedule::WalkWouldHang,
            };
        }
        let pick = (1..count)
            .map(|k| (self.last_used + k) % count)
            .find(|&i| within(&self.anchors[i]));
        match pick {
            Some(i) => {
                self.last_used = i;
                Schedule::Range(i)
            }
            None => Schedule::Idle,
        }
    }
}

/// The UWB position estimator (`px_uwb`, `py_uwb`).
#[derive(Debug, Clone, PartialEq)]
pub struct UwbEstimator {
    firmware: FirmwareProfile,
    px: f32,
    py: f32,
    /// 10.x: the copied fused yaw (degrees clockwise).
    yaw: f32,
    /// 12.x: the raw IMU yaw, counter-clockwise (`yaw_s = −imu_yaw`).
    yaw_s: f32,
    imu_yaw: f32,
    gyro_offset: f32,
    yaw_drift: f32,
    clamp_value: f32,
    clamped: bool,
    /// The yaw history's array; only the entries before `yaw_history_ptr` count.
    yaw_history: [f32; YAW_HISTORY],
    /// The firmware's pointer: entries since the last heading correction, restarting at 0 when it
    /// reaches [`YAW_HISTORY`] (so the mean covers only the entries since that restart).
    yaw_history_ptr: usize,
    p_old: (f32, f32),
    range_updates: u32,
    /// The largest correction per range ([`MAX_STEP_M`] unless a simulation changed it).
    max_step: f32,
}

impl UwbEstimator {
    /// The estimator after boot: at (0, 0).
    pub fn new(firmware: FirmwareVersion) -> Self {
        Self {
            firmware: firmware.profile(),
            px: 0.0,
            py: 0.0,
            yaw: 0.0,
            yaw_s: 0.0,
            imu_yaw: 0.0,
            gyro_offset: 0.0,
            yaw_drift: 0.0,
            clamp_value: 0.0,
            clamped: false,
            yaw_history: [0.0; YAW_HISTORY],
            yaw_history_ptr: 0,
            p_old: (0.0, 0.0),
            range_updates: 0,
            max_step: MAX_STEP_M,
        }
    }

    /// Changes the largest correction per range (simulation only: the firmware's is the constant
    /// [`MAX_STEP_M`]); what `drivecheck sweep` varies to show its trade-off.
    pub fn set_step_clamp(&mut self, metres: f32) {
        self.max_step = metres;
    }

    /// The estimate's position.
    pub fn position(&self) -> (f32, f32) {
        (self.px, self.py)
    }

    /// The reported UWB yaw (degrees clockwise): 10.x the copied yaw, 12.x `−(yaw_s + gyro_offset)`.
    pub fn yaw(&self) -> f32 {
        if self.firmware.uwb_estimator == Estimator::TrackedYaw {
            wrap180(-(self.yaw_s + self.gyro_offset))
        } else {
            self.yaw
        }
    }

    /// The pose the estimator holds.
    pub fn pose(&self) -> FwPose {
        FwPose {
            x: self.px,
            y: self.py,
            yaw: self.yaw(),
        }
    }

    /// 12.x internals for the debug view: `(gyro_offset, yaw_drift)`.
    pub fn yaw_state(&self) -> (f32, f32) {
        (self.gyro_offset, self.yaw_drift)
    }

    /// Dead reckoning at an odometry tick. `yaw` has passed the `uwb_yaw` probe: the fused yaw
    /// (10.x) or the raw IMU yaw (12.x); `distance` has passed `uwb_travel_dist`.
    pub fn dead_reckon(
        &mut self,
        distance: f32,
        yaw: f32,
        speed: f32,
        dt: f32,
        clamp_enabled: bool,
    ) {
        if self.firmware.uwb_estimator == Estimator::CopiedYaw {
            self.yaw = yaw;
            let a = -yaw.to_radians();
            self.px += distance * a.cos();
            self.py += distance * a.sin();
            return;
        }
        self.imu_yaw = yaw;
        self.yaw_s = -yaw;
        self.clamped = speed.abs() < CLAMP_SPEED && clamp_enabled;
        if self.clamped {
            self.gyro_offset = self.clamp_value - self.yaw_s;
        } else {
            self.clamp_value = self.yaw_s + self.gyro_offset;
        }
        let heading = (self.yaw_s + self.gyro_offset).to_radians();
        self.px += distance * heading.cos();
        self.py += distance * heading.sin();
        if !self.clamped {
            self.gyro_offset += self.yaw_drift * dt;
            self.push_yaw(self.yaw_s);
        }
        self.gyro_offset = wrap180(self.gyro_offset);
    }

    fn push_yaw(&mut self, yaw_s: f32) {
        self.yaw_history[self.yaw_history_ptr] = yaw_s;
        self.yaw_history_ptr += 1;
        if self.yaw_history_ptr >= YAW_HISTORY {
            self.yaw_history_ptr = 0;
        }
    }

    /// A range `r` to an anchor at `(ax, ay)` (after the probe). Returns whether the estimate
    /// moved.
    pub fn range_update(&mut self, ax: f32, ay: f32, r: f32, max_corr: f32) -> bool {
        let tracked = self.firmware.uwb_estimator == Estimator::TrackedYaw;
        let applied = if tracked {
            self.range_update_12x(ax, ay, r, max_corr)
        } else {
            self.range_update_10x(ax, ay, r)
        };
        if tracked {
            self.estimate_yaw();
        }
        applied
    }

    fn range_update_10x(&mut self, ax: f32, ay: f32, r: f32) -> bool {
        let a = -self.yaw.to_radians();
        let ant = (
            self.px + ANTENNA_OFFSET_M * a.cos(),
            self.py + ANTENNA_OFFSET_M * a.sin(),
        );
        let (dx, dy) = (ax - ant.0, ay - ant.1);
        let predicted = dx.hypot(dy).max(0.01);
        let diff = predicted - r;
        if diff.is_nan() || diff >= GATE_10X_M {
            return false;
        }
        let step = diff.abs().min(self.max_step).copysign(diff);
        self.px += step * dx / predicted;
        self.py += step * dy / predicted;
        true
    }

    fn range_update_12x(&mut self, ax: f32, ay: f32, r: f32, max_corr: f32) -> bool {
        // Quirk: the antenna direction mirrors the direction of motion and ignores gyro_offset.
        let a = self.imu_yaw.to_radians();
        let ant = (
            self.px + ANTENNA_OFFSET_M * a.cos(),
            self.py + ANTENNA_OFFSET_M * a.sin(),
        );
        let (dx, dy) = (ax - ant.0, ay - ant.1);
        let predicted = dx.hypot(dy);
        if predicted <= 0.0 || !predicted.is_finite() {
            // The firmware divides by zero here; the simulator skips the update.
            return false;
        }
        let diff = predicted - r;
        let c = if diff.abs() < max_corr {
            diff
        } else {
            self.max_step.copysign(diff)
        };
        if !c.is_finite() {
            return false;
        }
        self.px += c * dx / predicted;
        self.py += c * dy / predicted;
        true
    }

    /// 12.x heading estimation from the track of the estimate
    /// (`docs/firmware.md#uwb-estimator-12x`).
    fn estimate_yaw(&mut self) {
        let moved = if self.range_updates < 2 {
            self.p_old = (self.px, self.py);
            0.0
        } else {
            (self.px - self.p_old.0).hypot(self.py - self.p_old.1)
        };
        let history = &self.yaw_history[..self.yaw_history_ptr];
        if moved > 0.1 && !history.is_empty() && !self.clamped {
            let track = (self.py - self.p_old.1)
                .atan2(self.px - self.p_old.0)
                .to_degrees();
            let avg = history.iter().sum::<f32>() / history.len() as f32;
            let est = wrap180(track - avg);
            let delta = wrap180(est - self.gyro_offset);
            if delta.abs() < 0.25 {
                self.gyro_offset = est;
            } else if est > self.gyro_offset {
                self.gyro_offset += 0.25;
            } else {
                self.gyro_offset -= 0.25;
            }
            self.yaw_drift = (self.yaw_drift + 0.5 * delta).clamp(-3.5, 3.5);
            self.p_old = (self.px, self.py);
            self.yaw_history_ptr = 0;
        }
        self.range_updates = self.range_updates.saturating_add(1);
    }

    /// `pos_uwb_reset_pos`: 10.x copies the fused position and yaw, 12.x only the position.
    pub fn reset_to(&mut self, fused: FwPose) {
        self.px = fused.x;
        self.py = fused.y;
        if self.firmware.uwb_reset == UwbReset::PositionAndHeading {
            self.yaw = fused.yaw;
        }
    }

    /// SET_POS: position and heading.
    pub fn set_pose(&mut self, pose: FwPose) {
        self.px = pose.x;
        self.py = pose.y;
        if self.firmware.uwb_estimator == Estimator::TrackedYaw {
            self.gyro_offset = wrap180(-pose.yaw - self.yaw_s);
            self.clamp_value = self.yaw_s + self.gyro_offset;
        } else {
            self.yaw = pose.yaw;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::WorldAnchor;

    fn list(fw: FirmwareVersion, ids: &[i16]) -> AnchorList {
        let mut l = AnchorList::new(fw);
        for (k, id) in ids.iter().enumerate() {
            l.add(*id, k as f32 * 10.0, 0.0, 1.0);
        }
        l
    }

    #[test]
    fn round_robin_skips_the_last_used_anchor_and_starts_after_index_0() {
        let mut l = list(FirmwareVersion::V10_1, &[50, 234, 7]);
        let picks: Vec<Schedule> = (0..4).map(|_| l.schedule((0.0, 0.0))).collect();
        assert_eq!(
            picks,
            [
                Schedule::Range(1),
                Schedule::Range(2),
                Schedule::Range(0),
                Schedule::Range(1)
            ]
        );
    }

    #[test]
    fn a_single_anchor_is_never_ranged() {
        let mut l = list(FirmwareVersion::V10_1, &[50]);
        assert_eq!(l.schedule((0.0, 0.0)), Schedule::Idle);
    }

    #[test]
    fn the_80_m_gate_uses_the_estimate_and_can_stall() {
        let mut l = AnchorList::new(FirmwareVersion::V10_1);
        l.add(1, 0.0, 0.0, 1.0);
        l.add(2, 200.0, 0.0, 1.0);
        // Only index 0 is near; it is the last used at boot, so ranging stalls.
        assert_eq!(l.schedule((0.0, 0.0)), Schedule::Idle);
    }

    #[test]
    fn a_shrunk_list_would_hang_and_is_flagged() {
        let mut l = list(FirmwareVersion::V10_1, &[1, 2, 3]);
        l.schedule((0.0, 0.0));
        l.schedule((0.0, 0.0)); // last_used = 2
        l.clear();
        l.add(9, 500.0, 0.0, 1.0);
        assert_eq!(l.schedule((0.0, 0.0)), Schedule::WalkWouldHang);
    }

    #[test]
    fn duplicates_append_in_10x_and_update_in_12x() {
        let mut old = list(FirmwareVersion::V10_1, &[5, 5]);
        let mut new = list(FirmwareVersion::V12_3, &[5, 5]);
        assert_eq!(old.anchors().len(), 2);
        assert_eq!(new.anchors().len(), 1);
        assert_eq!(new.find_mut(5).unwrap().px, 10.0);
        assert!(old.find_mut(5).is_some());
        let mut many = AnchorList::new(FirmwareVersion::V12_3);
        for id in 0..30 {
            many.add(id, 0.0, 0.0, 0.0);
        }
        assert_eq!(many.anchors().len(), MAX_ANCHORS);
    }

    #[test]
    fn each_range_moves_the_10x_estimate_at_most_0_2_m_with_a_one_sided_gate() {
        let mut e = UwbEstimator::new(FirmwareVersion::V10_1);
        e.dead_reckon(0.0, 0.0, 0.0, 0.01, false);
        // Anchor 10 m east of the antenna; measured 12 m: move 0.2 m away.
        let ax = 10.0 + ANTENNA_OFFSET_M;
        assert!(e.range_update(ax, 0.0, 12.0, 0.1));
        assert!((e.position().0 + 0.2).abs() < 1e-5);
        // Measured 9 m shorter than predicted: ignored (diff ≥ 8).
        let before = e.position();
        assert!(!e.range_update(ax, 0.0, 1.0, 0.1));
        assert_eq!(e.position(), before);
        // A small error is corrected exactly.
        let mut e = UwbEstimator::new(FirmwareVersion::V10_1);
        e.range_update(ax, 0.0, 10.05, 0.1);
        assert!((e.position().0 + 0.05).abs() < 1e-4);
    }

    #[test]
    fn the_12x_step_jumps_to_0_2_beyond_max_corr_and_has_no_gate() {
        let mut e = UwbEstimator::new(FirmwareVersion::V12_3);
        e.dead_reckon(0.0, 0.0, 0.0, 0.02, true);
        let ax = 10.0 + ANTENNA_OFFSET_M;
        e.range_update(ax, 0.0, 10.15, 0.1);
        assert!((e.position().0 + 0.2).abs() < 1e-4, "overshoots to 0.2");
        let mut e = UwbEstimator::new(FirmwareVersion::V12_3);
        e.range_update(ax, 0.0, 0.0, 0.1);
        assert!(
            (e.position().0 - 0.2).abs() < 1e-4,
            "pulled towards the anchor"
        );
    }

    #[test]
    fn dead_reckoning_10x_copies_the_yaw_12x_integrates_gyro_offset() {
        let mut e = UwbEstimator::new(FirmwareVersion::V10_1);
        e.dead_reckon(1.0, 90.0, 1.0, 0.01, false);
        assert!((e.position().1 + 1.0).abs() < 1e-6);
        assert_eq!(e.yaw(), 90.0);
        let mut e = UwbEstimator::new(FirmwareVersion::V12_3);
        e.set_pose(FwPose {
            x: 0.0,
            y: 0.0,
            yaw: 0.0,
        });
        e.dead_reckon(1.0, 90.0, 1.0, 0.02, true);
        // Heading = yaw_s + gyro_offset = −90° CCW: south.
        assert!((e.position().1 + 1.0).abs() < 1e-6);
    }

    /// A 12.x range to a far anchor due north that agrees exactly with the estimate: the estimate
    /// does not move, only the heading estimation runs.
    fn agreeing_range(e: &mut UwbEstimator, imu_yaw: f32) {
        let (px, py) = e.position();
        let a = imu_yaw.to_radians();
        let antenna = (
            px + ANTENNA_OFFSET_M * a.cos(),
            py + ANTENNA_OFFSET_M * a.sin(),
        );
        let (ax, ay) = (0.0, 100.0);
        e.range_update(ax, ay, (ax - antenna.0).hypot(ay - antenna.1), 0.1);
    }

    #[test]
    fn the_12x_yaw_history_pointer_restarts_at_50_and_the_mean_covers_only_what_follows() {
        let mut e = UwbEstimator::new(FirmwareVersion::V12_3);
        e.dead_reckon(0.0, 0.0, 0.0, 0.02, true);
        agreeing_range(&mut e, 0.0);
        agreeing_range(&mut e, 0.0);
        // 50 ticks east at 0.5 m/s (IMU yaw 0°): the pointer is back at 0, the history counts as
        // empty, so a range after 0.5 m of travel corrects nothing and keeps p_old.
        for _ in 0..50 {
            e.dead_reckon(0.01, 0.0, 0.5, 0.02, true);
        }
        agreeing_range(&mut e, 0.0);
        assert_eq!(e.yaw_state(), (0.0, 0.0));
        // One more tick with the IMU at −20° (20° CCW): the mean is that single entry, not the
        // last 50, so the estimate (track ≈ 0.4° − 20°) pulls gyro_offset and saturates the drift.
        e.dead_reckon(0.01, -20.0, 0.5, 0.02, true);
        agreeing_range(&mut e, -20.0);
        let (offset, drift) = e.yaw_state();
        assert!((offset + 0.25).abs() < 1e-6, "{offset}");
        assert_eq!(drift, -3.5);
    }

    #[test]
    fn set_pos_sets_the_12x_heading_but_keeps_p_old_and_the_drift() {
        let mut e = UwbEstimator::new(FirmwareVersion::V12_3);
        e.dead_reckon(0.0, 0.0, 0.0, 0.02, true);
        agreeing_range(&mut e, 0.0);
        agreeing_range(&mut e, 0.0);
        // SET_POS 5 m north of p_old, heading east (yaw 0° clockwise).
        e.set_pose(FwPose {
            x: 0.0,
            y: 5.0,
            yaw: 0.0,
        });
        assert_eq!(e.yaw(), 0.0);
        e.dead_reckon(0.01, 0.0, 0.5, 0.02, true);
        assert!((e.position().0 - 0.01).abs() < 1e-6, "dead reckons east");
        // The first correction measures the track from the stale p_old: the jump reads as motion
        // to the north (`docs/firmware.md#resetting-the-estimate`: SET_POS sets px, py and
        // gyro_offset only).
        agreeing_range(&mut e, 0.0);
        assert_eq!(e.yaw_state(), (0.25, 3.5));
        // A second SET_POS restores the heading and keeps the drift.
        e.set_pose(FwPose {
            x: 0.0,
            y: 5.0,
            yaw: 30.0,
        });
        assert!((e.yaw() - 30.0).abs() < 1e-5);
        assert_eq!(e.yaw_state().1, 3.5);
    }

    #[test]
    fn reset_copies_position_only_in_12x() {
        let fused = FwPose {
            x: 3.0,
            y: 4.0,
            yaw: 30.0,
        };
        let mut old = UwbEstimator::new(FirmwareVersion::V10_1);
        old.reset_to(fused);
        assert_eq!(old.pose(), fused);
        let mut new = UwbEstimator::new(FirmwareVersion::V12_3);
        new.reset_to(fused);
        assert_eq!(new.position(), (3.0, 4.0));
        assert_eq!(new.yaw(), 0.0);
    }

    #[test]
    fn radio_model_measures_slant_range_with_bias_and_noise() {
        let world = World {
            anchors: vec![WorldAnchor {
                id: 50,
                position: Point::new(10.0, 0.0),
                height: 3.0,
                range_bias_m: None,
            }],
            ..World::default()
        };
        let radio = RadioModel {
            exchange_drop_probability: 0.0,
            anchor_bias_m: (0.0, 0.0),
            ..RadioModel::default()
        };
        let mut noise = Noise::stream(1, 1);
        let n = 400;
        let mut sum = 0.0;
        for _ in 0..n {
            let m = measure_range(&world, None, 50, Point::new(0.0, 0.0), &radio, &mut noise);
            match m.result {
                RangeResult::Measured(r) => sum += f64::from(r),
                other => panic!("{other:?}"),
            }
        }
        let expected = 10.0f64.hypot(2.0);
        // Truncation to whole mm biases the mean down by ~0.5 mm.
        assert!(
            (sum / n as f64 - expected).abs() < 0.01,
            "{}",
            sum / n as f64
        );
        let none = measure_range(&world, None, 51, Point::new(0.0, 0.0), &radio, &mut noise);
        assert_eq!(none.result, RangeResult::NoResponder);
    }

    /// The mean of many ranges to anchor 50 at 10 m with noise stream `stream`, minus the range.
    fn mean_error(radio: &RadioModel, stream: u64) -> f64 {
        let world = World {
            anchors: vec![WorldAnchor {
                id: 50,
                position: Point::new(10.0, 0.0),
                height: radio.antenna_height_m,
                range_bias_m: None,
            }],
            ..World::default()
        };
        let mut noise = Noise::stream(stream, 1);
        let n = 2000;
        let sum: f64 = (0..n)
            .filter_map(|_| {
                match measure_range(&world, None, 50, Point::new(0.0, 0.0), radio, &mut noise)
                    .result
                {
                    RangeResult::Measured(r) => Some(f64::from(r)),
                    _ => None,
                }
            })
            .sum();
        sum / f64::from(n) - 10.0
    }

    #[test]
    fn an_anchor_keeps_its_bias_whatever_the_noise_and_another_hardware_seed_changes_it() {
        let radio = RadioModel {
            exchange_drop_probability: 0.0,
            anchor_bias_m: (0.0, 1.0),
            ..RadioModel::default()
        };
        let bias = mean_error(&radio, 1);
        assert!((mean_error(&radio, 2) - bias).abs() < 0.02);
        let other = RadioModel {
            anchor_bias_seed: 7,
            ..radio
        };
        assert!((mean_error(&other, 1) - bias).abs() > 0.05);
    }
}
