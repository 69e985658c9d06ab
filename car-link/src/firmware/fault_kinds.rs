//! The fault kinds: one row each in [`KINDS`], holding everything drivecheck knows of a kind —
//! its name in files and on the terminal, what it does to a value, its neutral parameter, how
//! large a change it makes, how a scenario writes its range and the ranges that make sense on
//! each probe. Every other part (the simulated car, the client, scenario files, generation,
//! shrinking, explanations) reads the row, so adding a kind is a [`FaultKind`] variant and its row
//! (ARCHITECTURE.md, "Recipes").

use std::fmt;

use crate::fault::Probe;

/// What a fault does to the probed value (the firmware's fault types). With the `serde` feature
/// it is written as its [`KindSpec::name`] (`bitflip`, `offset`, `amplification`, `set_to`,
/// `none`), as in scenario and case files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema),
    serde(rename_all = "snake_case")
)]
pub enum FaultKind {
    /// Nothing, but it occupies a slot.
    None,
    /// XOR bit `clamp(trunc(param), 0, 31)` of the binary32 pattern.
    Bitflip,
    /// `x += param`.
    Offset,
    /// `x *= param`.
    Amplification,
    /// `x = param`.
    SetTo,
}

/// What a kind's parameter is, which says how a scenario writes its range
/// ([`KindSpec::scenario_key`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Param {
    /// A value in the probe's unit (metres, degrees), a float: written `<name>_<unit>`
    /// (`offset_m`, `set_to_deg`).
    Value,
    /// A factor without unit, a float: written `<name>` (`amplification`).
    Factor,
    /// A bit of the value's binary32 pattern, an integer 0–31: written `<name>_bits`.
    Bit,
    /// The kind takes none (its parameter is ignored); scenarios cannot draw it.
    Unused,
}

/// What a probe carries, which sets its unit and the scale of sensible fault parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Quantity {
    /// A measured range to one anchor, metres (`uwb_range_<id>`).
    Range,
    /// One odometry step fed to UWB dead reckoning, metres (`uwb_travel_dist`; 1–3 cm at test
    /// speeds).
    Travel,
    /// The yaw fed to UWB dead reckoning, degrees (`uwb_yaw`).
    Yaw,
    /// The fused position packed into GET_STATE, metres (`px`).
    Position,
}

impl Quantity {
    /// The unit as a scenario key writes it (`m`, `deg`).
    pub fn unit(self) -> &'static str {
        match self {
            Quantity::Range | Quantity::Travel | Quantity::Position => "m",
            Quantity::Yaw => "deg",
        }
    }
}

impl Probe {
    /// What the probe carries.
    pub fn quantity(&self) -> Quantity {
        match self {
            Probe::Px => Quantity::Position,
            Probe::UwbTravelDist => Quantity::Travel,
            Probe::UwbYaw => Quantity::Yaw,
            Probe::UwbRange(_) => Quantity::Range,
        }
    }
}

/// A kind's sensible parameter range on each quantity (`min`, `max`): what a scenario draws when
/// it lists the kind without giving a range. A position (`px`) takes the range's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Defaults {
    /// On an anchor's range.
    pub range: (f64, f64),
    /// On one odometry step.
    pub travel: (f64, f64),
    /// On the yaw.
    pub yaw: (f64, f64),
}

/// Everything drivecheck knows of one fault kind.
#[derive(Debug, Clone, Copy)]
pub struct KindSpec {
    /// The kind.
    pub kind: FaultKind,
    /// Its name in scenario and case files (`set_to`).
    pub name: &'static str,
    /// Its name on the terminal (`SET_TO`), as `fi_add_fault` takes it and `fi_print_faults`
    /// prints it.
    pub terminal: &'static str,
    /// Whether the firmware also takes the terminal name in lower or mixed case (it does for
    /// `NONE` only).
    pub terminal_any_case: bool,
    /// What its parameter is.
    pub param: Param,
    /// The parameter that leaves every value as it is (`None` when the change depends on the
    /// value: set_to, bitflip). Shrinking moves a parameter toward it.
    pub neutral: Option<f64>,
    /// What the fault does to value `x` with parameter `param`, `elapsed` probe calls after it
    /// started (0 at its first), as the firmware applies it.
    pub apply: fn(x: f32, param: f32, elapsed: u32) -> f32,
    /// Its sensible parameter ranges per quantity.
    pub defaults: Defaults,
    /// The quantities on which a scenario draws it when the scenario lists no kinds (the
    /// method's faults: offset and amplification on ranges, amplification on odometry, offset on
    /// the yaw).
    pub drawn_by_default: &'static [Quantity],
    /// Whether a fault of this kind on the yaw turns the dead-reckoned heading by its parameter
    /// (degrees) whatever the yaw is: a kind that adds its parameter (`x += param`). Explaining a
    /// segment turns the direction such a fault moves the estimate in (`campaign::explain`).
    pub turns_heading_by_param: bool,
}

/// The bits a generated `bitflip` flips by default: the top of the mantissa (18–22: the value
/// changes by 3–50 %), the exponent (23–30: it is halved or doubled up to a blow-up to ±inf or
/// near 0) and the sign (31).
const BITFLIP_BITS: (f64, f64) = (18.0, 31.0);

/// The table: one row per kind, in the order scenario files write their ranges.
pub const KINDS: [KindSpec; 5] = [
    KindSpec {
        kind: FaultKind::Offset,
        name: "offset",
        terminal: "OFFSET",
        terminal_any_case: false,
        param: Param::Value,
        neutral: Some(0.0),
        apply: |x, param, _| x + param,
        defaults: Defaults {
            range: (0.0, 5.0),
            travel: (0.0, 0.05),
            yaw: (-20.0, 20.0),
        },
        drawn_by_default: &[Quantity::Range, Quantity::Yaw],
        turns_heading_by_param: true,
    },
    KindSpec {
        kind: FaultKind::Amplification,
        name: "amplification",
        terminal: "AMPLIFICATION",
        terminal_any_case: false,
        param: Param::Factor,
        neutral: Some(1.0),
        apply: |x, param, _| x * param,
        defaults: Defaults {
            range: (0.0, 5.0),
            travel: (1.0, 5.0),
            yaw: (0.5, 1.5),
        },
        drawn_by_default: &[Quantity::Range, Quantity::Travel],
        turns_heading_by_param: false,
    },
    KindSpec {
        kind: FaultKind::SetTo,
        name: "set_to",
        terminal: "SET_TO",
        terminal_any_case: false,
        param: Param::Value,
        neutral: None,
        apply: |_, param, _| param,
        defaults: Defaults {
            range: (0.0, 20.0),
            travel: (0.0, 0.05),
            yaw: (-180.0, 180.0),
        },
        drawn_by_default: &[],
        turns_heading_by_param: false,
    },
    KindSpec {
        kind: FaultKind::Bitflip,
        name: "bitflip",
        terminal: "BITFLIP",
        terminal_any_case: false,
        param: Param::Bit,
        neutral: None,
        // C: (int)param, then clamped to 0..31; `as` saturates and maps NaN to 0 like a clamp
        // would.
        apply: |x, param, _| f32::from_bits(x.to_bits() ^ (1u32 << (param as i32).clamp(0, 31))),
        defaults: Defaults {
            range: BITFLIP_BITS,
            travel: BITFLIP_BITS,
            yaw: BITFLIP_BITS,
        },
        drawn_by_default: &[],
        turns_heading_by_param: false,
    },
    KindSpec {
        kind: FaultKind::None,
        name: "none",
        terminal: "NONE",
        terminal_any_case: true,
        param: Param::Unused,
        neutral: None,
        apply: |x, _, _| x,
        defaults: Defaults {
            range: (0.0, 0.0),
            travel: (0.0, 0.0),
            yaw: (0.0, 0.0),
        },
        drawn_by_default: &[],
        turns_heading_by_param: false,
    },
];

impl FaultKind {
    /// Every kind, in the table's order.
    pub fn all() -> impl Iterator<Item = FaultKind> {
        KINDS.iter().map(|spec| spec.kind)
    }

    /// The kinds a scenario can draw (those with a parameter), in the table's order.
    pub fn drawable() -> impl Iterator<Item = FaultKind> {
        KINDS
            .iter()
            .filter(|spec| spec.param != Param::Unused)
            .map(|spec| spec.kind)
    }

    /// The kind's row of [`KINDS`].
    pub fn spec(self) -> &'static KindSpec {
        // The row's index (`every_kind_has_one_row` checks that it holds the kind).
        &KINDS[match self {
            FaultKind::Offset => 0,
            FaultKind::Amplification => 1,
            FaultKind::SetTo => 2,
            FaultKind::Bitflip => 3,
            FaultKind::None => 4,
        }]
    }

    /// The kind's name in scenario and case files (`set_to`).
    pub fn name(self) -> &'static str {
        self.spec().name
    }

    /// The kind a terminal name stands for, as the firmware parses it (`NONE` in any case, the
    /// others upper case only).
    pub fn from_terminal(text: &str) -> Option<FaultKind> {
        KINDS
            .iter()
            .find(|spec| {
                spec.terminal == text
                    || (spec.terminal_any_case && spec.terminal.eq_ignore_ascii_case(text))
            })
            .map(|spec| spec.kind)
    }

    /// What the fault does to `x` with parameter `param`, `elapsed` probe calls after it started.
    pub fn apply(self, x: f32, param: f32, elapsed: u32) -> f32 {
        (self.spec().apply)(x, param, elapsed)
    }

    /// How much the fault changes a value, comparable between faults of one kind without the
    /// value: `|param − neutral|` (|offset|, |factor − 1|); `None` for kinds without a neutral
    /// parameter (set_to, bitflip, none).
    pub fn size(self, param: f64) -> Option<f64> {
        self.spec().neutral.map(|neutral| (param - neutral).abs())
    }

    /// The kind's sensible parameter range on `quantity`.
    pub fn default_range(self, quantity: Quantity) -> (f64, f64) {
        let defaults = self.spec().defaults;
        match quantity {
            Quantity::Range | Quantity::Position => defaults.range,
            Quantity::Travel => defaults.travel,
            Quantity::Yaw => defaults.yaw,
        }
    }

    /// Whether a scenario draws the kind on `quantity` when it lists no kinds.
    pub fn drawn_by_default(self, quantity: Quantity) -> bool {
        self.spec().drawn_by_default.contains(&quantity)
    }

    /// The key a scenario writes the kind's range under on `quantity` (`offset_m`, `set_to_deg`,
    /// `amplification`, `bitflip_bits`); `None` for a kind without a parameter.
    pub fn scenario_key(self, quantity: Quantity) -> Option<String> {
        let spec = self.spec();
        match spec.param {
            Param::Value => Some(format!("{}_{}", spec.name, quantity.unit())),
            Param::Factor => Some(spec.name.to_owned()),
            Param::Bit => Some(format!("{}_bits", spec.name)),
            Param::Unused => None,
        }
    }
}

impl fmt::Display for FaultKind {
    /// The terminal name (`SET_TO`).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.spec().terminal)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const EVERY_VARIANT: [FaultKind; 5] = [
        FaultKind::None,
        FaultKind::Bitflip,
        FaultKind::Offset,
        FaultKind::Amplification,
        FaultKind::SetTo,
    ];

    #[test]
    fn every_kind_has_one_row() {
        for kind in EVERY_VARIANT {
            assert_eq!(
                KINDS.iter().filter(|s| s.kind == kind).count(),
                1,
                "{kind:?}"
            );
            assert_eq!(kind.spec().kind, kind);
        }
        assert_eq!(KINDS.len(), EVERY_VARIANT.len());
    }

    #[test]
    fn terminal_names_parse_as_the_firmware_parses_them() {
        for kind in FaultKind::all() {
            assert_eq!(FaultKind::from_terminal(&kind.to_string()), Some(kind));
        }
        assert_eq!(FaultKind::from_terminal("none"), Some(FaultKind::None));
        assert_eq!(FaultKind::from_terminal("NoNe"), Some(FaultKind::None));
        assert_eq!(FaultKind::from_terminal("offset"), None);
        assert_eq!(FaultKind::from_terminal("DRIFT"), None);
    }

    #[test]
    fn effects_are_the_firmwares() {
        assert_eq!(FaultKind::Offset.apply(1.5, 4.0, 0), 5.5);
        assert_eq!(FaultKind::Amplification.apply(1.5, 0.0, 3), 0.0);
        assert_eq!(FaultKind::SetTo.apply(1.5, -2.0, 0), -2.0);
        assert_eq!(FaultKind::None.apply(1.5, 9.0, 0), 1.5);
        assert_eq!(FaultKind::Bitflip.apply(2.0, 31.0, 0), -2.0);
        assert_eq!(FaultKind::Bitflip.apply(2.0, 22.0, 0), 3.0);
        // The bit is clamped to 0..31, as the firmware's C does.
        assert_eq!(
            FaultKind::Bitflip.apply(2.0, 99.0, 0),
            FaultKind::Bitflip.apply(2.0, 31.0, 0)
        );
        assert_eq!(
            FaultKind::Bitflip.apply(2.0, -5.0, 0),
            FaultKind::Bitflip.apply(2.0, 0.0, 0)
        );
        assert_eq!(FaultKind::Bitflip.apply(1.0, 30.0, 0), f32::INFINITY);
    }

    #[test]
    fn a_neutral_parameter_changes_nothing() {
        for spec in KINDS {
            if let Some(neutral) = spec.neutral {
                for x in [-3.5f32, 0.0, 0.25, 1e6] {
                    assert_eq!((spec.apply)(x, neutral as f32, 7), x, "{}", spec.name);
                }
                assert_eq!(spec.kind.size(neutral), Some(0.0));
            } else {
                assert_eq!(spec.kind.size(1.0), None);
            }
        }
    }

    #[test]
    fn scenario_keys_carry_the_unit() {
        assert_eq!(
            FaultKind::Offset.scenario_key(Quantity::Yaw).as_deref(),
            Some("offset_deg")
        );
        assert_eq!(
            FaultKind::SetTo.scenario_key(Quantity::Travel).as_deref(),
            Some("set_to_m")
        );
        assert_eq!(
            FaultKind::Amplification
                .scenario_key(Quantity::Range)
                .as_deref(),
            Some("amplification")
        );
        assert_eq!(
            FaultKind::Bitflip.scenario_key(Quantity::Yaw).as_deref(),
            Some("bitflip_bits")
        );
        assert_eq!(FaultKind::None.scenario_key(Quantity::Range), None);
    }

    #[test]
    fn default_ranges_are_ordered_and_drawable_kinds_have_a_parameter() {
        for spec in KINDS {
            for q in [Quantity::Range, Quantity::Travel, Quantity::Yaw] {
                let (min, max) = spec.kind.default_range(q);
                assert!(min <= max, "{} on {q:?}", spec.name);
                if spec.drawn_by_default.contains(&q) {
                    assert_ne!(spec.param, Param::Unused);
                }
            }
        }
        assert_eq!(
            FaultKind::drawable().collect::<Vec<_>>(),
            [
                FaultKind::Offset,
                FaultKind::Amplification,
                FaultKind::SetTo,
                FaultKind::Bitflip
            ]
        );
    }
}
