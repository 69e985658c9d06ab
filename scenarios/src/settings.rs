//! Vehicle, generator and campaign settings: every field has the method's default.

use serde::{Deserialize, Serialize};
use trajgen::{Constraints, GeneratorConfig, Strategy};

/// An inclusive range `min..=max` (also the `{min, max}` ranges of a case file's settings).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Interval<T> {
    /// Smallest value.
    pub min: T,
    /// Largest value.
    pub max: T,
}

impl<T> Interval<T> {
    /// The range `min..=max`.
    pub const fn new(min: T, max: T) -> Self {
        Self { min, max }
    }
}

/// The car's geometry (defaults: the reference firmware's, `docs/firmware.md#vehicle-parameters`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Vehicle {
    /// Distance between the axles, metres (0.475).
    pub wheelbase_m: f64,
    /// Largest steering angle of the front wheels, radians (0.42041, i.e. 24.09°; minimum turning
    /// radius 1.062 m).
    pub max_steering_angle_rad: f64,
    /// Width of the car, metres (0.5, an estimate for the 1:6 model car; not a firmware parameter).
    pub width_m: f64,
}

impl Default for Vehicle {
    fn default() -> Self {
        Self {
            wheelbase_m: 0.475,
            max_steering_angle_rad: 0.42041,
            width_m: 0.5,
        }
    }
}

impl Vehicle {
    /// The smallest turning radius, `wheelbase / tan(max steering angle)`, metres.
    pub fn min_turning_radius_m(&self) -> f64 {
        self.wheelbase_m / self.max_steering_angle_rad.tan()
    }
}

/// The trajectory generator's constants (`docs/method.md#drivable-trajectories`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GeneratorSettings {
    /// Shortest segment, metres (0.6).
    pub segment_min_m: f64,
    /// Longest segment, metres (2.0).
    pub segment_max_m: f64,
    /// Largest heading change between consecutive segments, degrees; turns must be strictly
    /// smaller (30).
    pub max_turn_deg: f64,
    /// Points generated beyond each extension to prove a drivable continuation exists (20).
    pub ahead_margin: usize,
    /// The ahead margin used when planning return routes (15).
    pub recovery_ahead_margin: usize,
    /// Sampled candidates per point before an attempt is abandoned (50).
    pub inner_tries: usize,
    /// Attempts per extension before generation fails (5000).
    pub outer_tries: usize,
    /// Distance every generated segment keeps from every edge, metres (0.5; 0: none). The method
    /// has none, but the car is 0.5 m wide and its pure-pursuit autopilot cuts corners: on routes
    /// touching the fence it left the fence by up to 0.4 m, beyond the safety monitor's 0.3 m
    /// margin. Return routes from a car standing inside this band keep less (see
    /// `recovery::PlanConfig::plan_with_fallback`).
    pub clearance_m: f64,
}

impl Default for GeneratorSettings {
    fn default() -> Self {
        Self {
            segment_min_m: 0.6,
            segment_max_m: 2.0,
            max_turn_deg: 30.0,
            ahead_margin: 20,
            recovery_ahead_margin: 15,
            inner_tries: 50,
            outer_tries: 5000,
            clearance_m: 0.5,
        }
    }
}

impl GeneratorSettings {
    /// The trajectory generator's configuration for these settings, with the chosen strategy.
    /// Tries beyond `u32::MAX` are capped there.
    pub fn generator_config(&self, strategy: Strategy) -> GeneratorConfig {
        let mut config = GeneratorConfig::default()
            .with_constraints(self.constraints())
            .with_ahead_margin(self.ahead_margin)
            .with_strategy(strategy);
        config.inner_tries = u32::try_from(self.inner_tries).unwrap_or(u32::MAX);
        config.outer_tries = u32::try_from(self.outer_tries).unwrap_or(u32::MAX);
        config
    }

    /// The constraints of [`trajgen`] these settings describe.
    pub fn constraints(&self) -> Constraints {
        Constraints {
            min_segment: self.segment_min_m,
            max_segment: self.segment_max_m,
            max_turn: self.max_turn_deg.to_radians(),
            clearance: self.clearance_m,
        }
    }

    /// How far the recovery route's last point may be from the start route's first point:
    /// 1.5 × [`Self::segment_max_m`].
    pub fn recovery_join_max_m(&self) -> f64 {
        RECOVERY_JOIN_FACTOR * self.segment_max_m
    }
}

/// The recovery route must end within this many longest segments of the start route's first point.
pub const RECOVERY_JOIN_FACTOR: f64 = 1.5;

/// Defaults for campaigns run in a scenario (`docs/method.md#the-model`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CampaignSettings {
    /// Tests per campaign (10).
    pub tests: usize,
    /// Commands per test, growing over the campaign (5–20).
    pub test_size: Interval<usize>,
    /// Points per RunSegments extension (4–7).
    pub points_per_segment: Interval<usize>,
    /// Speed of an extension, km/h (3–12).
    pub speed_kmh: Interval<f64>,
    /// The oracle: largest allowed UWB deviation from RTK, metres (1.0).
    pub oracle_threshold_m: f64,
    /// How often each command is chosen.
    pub weights: CommandWeights,
    /// Parameter ranges of the injected faults.
    pub faults: FaultSettings,
}

impl Default for CampaignSettings {
    fn default() -> Self {
        Self {
            tests: 10,
            test_size: Interval::new(5, 20),
            points_per_segment: Interval::new(4, 7),
            speed_kmh: Interval::new(3.0, 12.0),
            oracle_threshold_m: 1.0,
            weights: CommandWeights::default(),
            faults: FaultSettings::default(),
        }
    }
}

/// Relative weights of the commands in a test (0 disables a fault command).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CommandWeights {
    /// RunSegments (4); must be positive.
    pub run_segments: u32,
    /// AddFault on one anchor's range (2).
    pub anchor_range_fault: u32,
    /// AddFault wheel slip (1).
    pub wheel_slip_fault: u32,
    /// AddFault yaw (1).
    pub yaw_fault: u32,
}

impl Default for CommandWeights {
    fn default() -> Self {
        Self {
            run_segments: 4,
            anchor_range_fault: 2,
            wheel_slip_fault: 1,
            yaw_fault: 1,
        }
    }
}

/// Parameter ranges of the three fault commands. Start and duration count probe iterations.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FaultSettings {
    /// Reflection / NLOS on one anchor's range (probe `uwb_range_<id>`).
    pub anchor_range: AnchorRangeFault,
    /// Odometry over-reading (probe `uwb_travel_dist`).
    pub wheel_slip: WheelSlipFault,
    /// Heading error (probe `uwb_yaw`).
    pub yaw: YawFault,
}

/// The firmware's fault types (`offset`, `amplification`, `set_to`, `bitflip`; `none` is refused
/// in scenarios: it does nothing), as car-link names them.
pub use car_link::fault::FaultKind;

/// The bits a generated `bitflip` flips by default: the top of the mantissa (18–22: the value
/// changes by 3–50 %), the exponent (23–30: it is halved or doubled up to a blow-up to ±inf or
/// near 0) and the sign (31).
pub const DEFAULT_BITFLIP_BITS: Interval<u32> = Interval::new(18, 31);

/// The name of a fault kind in scenario and case files.
pub fn fault_kind_name(kind: FaultKind) -> &'static str {
    match kind {
        FaultKind::None => "none",
        FaultKind::Bitflip => "bitflip",
        FaultKind::Offset => "offset",
        FaultKind::Amplification => "amplification",
        FaultKind::SetTo => "set_to",
    }
}

/// Ranges of the anchor range fault.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AnchorRangeFault {
    /// Fault types to choose from (offset and amplification by default; set_to and bitflip when
    /// listed).
    pub kinds: Vec<FaultKind>,
    /// The parameter of an offset (metres) or an amplification (a factor) (0–5).
    pub param: Interval<f64>,
    /// The range a `set_to` fault reports, metres (0–20).
    pub set_to_m: Interval<f64>,
    /// The bit a `bitflip` fault flips (18–31, see [`DEFAULT_BITFLIP_BITS`]).
    pub bitflip_bits: Interval<u32>,
    /// Probe iteration at which the fault starts (0–100).
    pub start: Interval<u32>,
    /// Probe iterations it lasts (1–8).
    pub duration: Interval<u32>,
}

impl Default for AnchorRangeFault {
    fn default() -> Self {
        Self {
            kinds: vec![FaultKind::Offset, FaultKind::Amplification],
            param: Interval::new(0.0, 5.0),
            set_to_m: Interval::new(0.0, 20.0),
            bitflip_bits: DEFAULT_BITFLIP_BITS,
            start: Interval::new(0, 100),
            duration: Interval::new(1, 8),
        }
    }
}

/// Ranges of the wheel slip fault (by default an amplification of the travelled distance). One
/// call of the probe is one odometry step: 1–3 cm at test speeds.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WheelSlipFault {
    /// Fault types to choose from (amplification by default).
    pub kinds: Vec<FaultKind>,
    /// Amplification factor (1.0–5.0).
    pub amplification: Interval<f64>,
    /// The distance an `offset` fault adds to one odometry step, metres (0–0.05).
    pub offset_m: Interval<f64>,
    /// The distance a `set_to` fault reports for one odometry step, metres (0–0.05).
    pub set_to_m: Interval<f64>,
    /// The bit a `bitflip` fault flips (18–31).
    pub bitflip_bits: Interval<u32>,
    /// Probe iteration at which the fault starts (0–100).
    pub start: Interval<u32>,
    /// Probe iterations it lasts (1–10).
    pub duration: Interval<u32>,
}

impl Default for WheelSlipFault {
    fn default() -> Self {
        Self {
            kinds: vec![FaultKind::Amplification],
            amplification: Interval::new(1.0, 5.0),
            offset_m: Interval::new(0.0, 0.05),
            set_to_m: Interval::new(0.0, 0.05),
            bitflip_bits: DEFAULT_BITFLIP_BITS,
            start: Interval::new(0, 100),
            duration: Interval::new(1, 10),
        }
    }
}

/// Ranges of the yaw fault (by default an offset on the heading fed to the UWB estimator,
/// degrees).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct YawFault {
    /// Fault types to choose from (offset by default).
    pub kinds: Vec<FaultKind>,
    /// Offset, degrees (−20..20).
    pub offset_deg: Interval<f64>,
    /// Amplification factor (0.5–1.5).
    pub amplification: Interval<f64>,
    /// The heading a `set_to` fault reports, degrees (−180..180).
    pub set_to_deg: Interval<f64>,
    /// The bit a `bitflip` fault flips (18–31).
    pub bitflip_bits: Interval<u32>,
    /// Probe iteration at which the fault starts (0–100).
    pub start: Interval<u32>,
    /// Probe iterations it lasts (1–10).
    pub duration: Interval<u32>,
}

impl Default for YawFault {
    fn default() -> Self {
        Self {
            kinds: vec![FaultKind::Offset],
            offset_deg: Interval::new(-20.0, 20.0),
            amplification: Interval::new(0.5, 1.5),
            set_to_deg: Interval::new(-180.0, 180.0),
            bitflip_bits: DEFAULT_BITFLIP_BITS,
            start: Interval::new(0, 100),
            duration: Interval::new(1, 10),
        }
    }
}
