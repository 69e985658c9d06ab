//! Vehicle, generator and campaign settings: every field has the method's default.

use std::collections::BTreeMap;

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

/// The three fault commands a campaign draws (a scenario's `[campaign.faults.<section>]`), each
/// on its probes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum FaultTarget {
    /// Reflection / NLOS on one anchor's range (probe `uwb_range_<id>`).
    AnchorRange,
    /// Odometry over-reading (probe `uwb_travel_dist`).
    WheelSlip,
    /// Heading error (probe `uwb_yaw`).
    Yaw,
}

impl FaultTarget {
    /// The three, in the order scenario files write them.
    pub const ALL: [FaultTarget; 3] = [
        FaultTarget::AnchorRange,
        FaultTarget::WheelSlip,
        FaultTarget::Yaw,
    ];

    /// The section's name (`anchor_range`).
    pub fn section(self) -> &'static str {
        match self {
            FaultTarget::AnchorRange => "anchor_range",
            FaultTarget::WheelSlip => "wheel_slip",
            FaultTarget::Yaw => "yaw",
        }
    }

    /// What its probes carry.
    pub fn quantity(self) -> Quantity {
        match self {
            FaultTarget::AnchorRange => Quantity::Range,
            FaultTarget::WheelSlip => Quantity::Travel,
            FaultTarget::Yaw => Quantity::Yaw,
        }
    }

    /// The kinds it draws when a scenario lists none (the fault table's defaults).
    pub fn default_kinds(self) -> Vec<FaultKind> {
        FaultKind::drawable()
            .filter(|kind| kind.drawn_by_default(self.quantity()))
            .collect()
    }

    /// The key a scenario writes `kind`'s range under in this section (`offset_deg`); `None` for
    /// a kind without a parameter.
    pub fn key(self, kind: FaultKind) -> Option<String> {
        kind.scenario_key(self.quantity())
    }
}

/// The key under which `anchor_range` gives one range for both offset and amplification (the
/// format's first form, still read and written when the two ranges are equal).
pub const SHARED_PARAM_KEY: &str = "param";

/// One fault command's ranges: the kinds it draws, the parameter range of every kind (a map kind
/// → range, so a new kind in the fault table needs no field here), when it starts and how long it
/// lasts. Start and duration count probe iterations.
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeFaults {
    /// Fault types to choose from.
    pub kinds: Vec<FaultKind>,
    /// The parameter range of every kind with a parameter (the table's default where the file
    /// gives none); a bitflip's range holds bit numbers.
    pub ranges: BTreeMap<FaultKind, Interval<f64>>,
    /// Probe iteration at which the fault starts (0–100).
    pub start: Interval<u32>,
    /// Probe iterations it lasts (1–8 on ranges, 1–10 otherwise).
    pub duration: Interval<u32>,
}

impl ProbeFaults {
    /// The method's ranges of `target` (the fault table's defaults).
    pub fn defaults(target: FaultTarget) -> Self {
        let quantity = target.quantity();
        Self {
            kinds: target.default_kinds(),
            ranges: FaultKind::drawable()
                .map(|kind| {
                    let (min, max) = kind.default_range(quantity);
                    (kind, Interval::new(min, max))
                })
                .collect(),
            start: Interval::new(0, 100),
            duration: match target {
                FaultTarget::AnchorRange => Interval::new(1, 8),
                FaultTarget::WheelSlip | FaultTarget::Yaw => Interval::new(1, 10),
            },
        }
    }

    /// The parameter range of `kind` (a kind without a parameter: `0..=0`).
    pub fn range(&self, kind: FaultKind) -> Interval<f64> {
        self.ranges
            .get(&kind)
            .copied()
            .unwrap_or(Interval::new(0.0, 0.0))
    }

    /// Whether `target`'s section writes its offset and amplification ranges as one
    /// [`SHARED_PARAM_KEY`]: anchor_range's, while the two are equal (the format's first form).
    pub fn shares_param(&self, target: FaultTarget) -> bool {
        target == FaultTarget::AnchorRange
            && self.range(FaultKind::Offset) == self.range(FaultKind::Amplification)
    }
}

/// Parameter ranges of the three fault commands.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(try_from = "RawFaultSettings")]
pub struct FaultSettings {
    /// Reflection / NLOS on one anchor's range (offset and amplification by default).
    pub anchor_range: ProbeFaults,
    /// Odometry over-reading (amplification by default; one call of the probe is one odometry
    /// step: 1–3 cm at test speeds).
    pub wheel_slip: ProbeFaults,
    /// Heading error (an offset on the heading fed to the UWB estimator, degrees, by default).
    pub yaw: ProbeFaults,
}

impl Default for FaultSettings {
    fn default() -> Self {
        Self {
            anchor_range: ProbeFaults::defaults(FaultTarget::AnchorRange),
            wheel_slip: ProbeFaults::defaults(FaultTarget::WheelSlip),
            yaw: ProbeFaults::defaults(FaultTarget::Yaw),
        }
    }
}

impl FaultSettings {
    /// The ranges of `target`.
    pub fn get(&self, target: FaultTarget) -> &ProbeFaults {
        match target {
            FaultTarget::AnchorRange => &self.anchor_range,
            FaultTarget::WheelSlip => &self.wheel_slip,
            FaultTarget::Yaw => &self.yaw,
        }
    }

    /// The ranges of `target`, to change.
    pub fn get_mut(&mut self, target: FaultTarget) -> &mut ProbeFaults {
        match target {
            FaultTarget::AnchorRange => &mut self.anchor_range,
            FaultTarget::WheelSlip => &mut self.wheel_slip,
            FaultTarget::Yaw => &mut self.yaw,
        }
    }
}

/// The firmware's fault types (`offset`, `amplification`, `set_to`, `bitflip`; `none` is refused
/// in scenarios: it does nothing), as car-link's fault table names them.
pub use car_link::fault::FaultKind;
use car_link::firmware::Quantity;

/// The `[campaign.faults]` table as written: each section's keys as they come.
#[derive(Debug, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct RawFaultSettings {
    anchor_range: RawProbeFaults,
    wheel_slip: RawProbeFaults,
    yaw: RawProbeFaults,
}

/// One section as written: its kinds, start and duration, and every other key a range (which
/// kind's, the section's quantity says: [`FaultTarget::key`]).
#[derive(Debug, Default)]
struct RawProbeFaults {
    kinds: Option<Vec<FaultKind>>,
    start: Option<Interval<u32>>,
    duration: Option<Interval<u32>>,
    ranges: Vec<(String, Interval<f64>)>,
}

impl<'de> Deserialize<'de> for RawProbeFaults {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = RawProbeFaults;

            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a table of fault kinds, ranges, start and duration")
            }

            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut map: A,
            ) -> Result<RawProbeFaults, A::Error> {
                let mut raw = RawProbeFaults::default();
                while let Some(key) = map.next_key::<String>()? {
                    let duplicate = match key.as_str() {
                        "kinds" => raw.kinds.replace(map.next_value()?).is_some(),
                        "start" => raw.start.replace(map.next_value()?).is_some(),
                        "duration" => raw.duration.replace(map.next_value()?).is_some(),
                        _ => {
                            let duplicate = raw.ranges.iter().any(|(k, _)| *k == key);
                            raw.ranges.push((key.clone(), map.next_value()?));
                            duplicate
                        }
                    };
                    if duplicate {
                        return Err(serde::de::Error::custom(format!("duplicate key `{key}`")));
                    }
                }
                Ok(raw)
            }
        }
        deserializer.deserialize_map(Visitor)
    }
}

/// A `[campaign.faults.<section>]` key that names no range of the section, or two keys for one.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FaultKeyError {
    /// A key the section does not have.
    #[error("unknown field `{key}` in {section}, expected one of {expected}")]
    Unknown {
        /// The section (`yaw`).
        section: &'static str,
        /// The key as written.
        key: String,
        /// The section's keys, quoted and comma-separated.
        expected: String,
    },
    /// Two keys giving one kind's range (`param` and `offset_m`).
    #[error("{section}.{first} and {section}.{second} both give the range of {kind}")]
    Twice {
        /// The section.
        section: &'static str,
        /// The key read first.
        first: String,
        /// The key read second.
        second: String,
        /// The kind's name.
        kind: &'static str,
    },
}

impl TryFrom<RawFaultSettings> for FaultSettings {
    type Error = FaultKeyError;

    fn try_from(raw: RawFaultSettings) -> Result<Self, Self::Error> {
        Ok(Self {
            anchor_range: raw.anchor_range.build(FaultTarget::AnchorRange)?,
            wheel_slip: raw.wheel_slip.build(FaultTarget::WheelSlip)?,
            yaw: raw.yaw.build(FaultTarget::Yaw)?,
        })
    }
}

impl RawProbeFaults {
    /// The section's ranges over the defaults of `target`; an error names a key the section
    /// does not have.
    fn build(self, target: FaultTarget) -> Result<ProbeFaults, FaultKeyError> {
        let mut out = ProbeFaults::defaults(target);
        out.kinds = self.kinds.unwrap_or(out.kinds);
        out.start = self.start.unwrap_or(out.start);
        out.duration = self.duration.unwrap_or(out.duration);
        let shared = target == FaultTarget::AnchorRange;
        let section = target.section();
        // Which key gave each kind's range, to refuse two keys for one kind.
        let mut given: BTreeMap<FaultKind, String> = BTreeMap::new();
        for (key, range) in self.ranges {
            let kinds = if shared && key == SHARED_PARAM_KEY {
                vec![FaultKind::Offset, FaultKind::Amplification]
            } else if let Some(kind) =
                FaultKind::drawable().find(|&k| target.key(k).as_deref() == Some(key.as_str()))
            {
                vec![kind]
            } else {
                let expected: Vec<String> = ["kinds".to_owned(), "start".into(), "duration".into()]
                    .into_iter()
                    .chain(shared.then(|| SHARED_PARAM_KEY.to_owned()))
                    .chain(FaultKind::drawable().filter_map(|k| target.key(k)))
                    .map(|k| format!("`{k}`"))
                    .collect();
                return Err(FaultKeyError::Unknown {
                    section,
                    key,
                    expected: expected.join(", "),
                });
            };
            for kind in kinds {
                if let Some(first) = given.insert(kind, key.clone()) {
                    return Err(FaultKeyError::Twice {
                        section,
                        first,
                        second: key,
                        kind: kind.name(),
                    });
                }
                out.ranges.insert(kind, range);
            }
        }
        Ok(out)
    }
}
