//! Car profiles: what a simulated car is like beyond its scenario — its firmware, its radio, its
//! anchors as they really stand, its odometry, IMU and GNSS (`docs/twin.md`).
//!
//! A profile is a TOML file (`format = "drivecheck-car-profile"`, `version = 1`). Every section
//! and field may be left out: what is not written is the default car's ([`CarProfile::default`],
//! the simulated car drivecheck has always had). [`CarProfile::apply`] makes a [`SimConfig`] that
//! car. [`CarProfile::to_toml`] writes the canonical form, every field, and [`CarProfile::hash`]
//! is the SHA-256 of it, so two files that load to the same car have the same hash whatever
//! their comments and layout.
//!
//! | field | unit | simulator |
//! |---|---|---|
//! | `firmware` | `MAJOR.MINOR` | [`SimConfig::firmware`] |
//! | `radio.range_sigma_m` | m | [`RadioModel::exchange_sigma_m`] |
//! | `radio.exchange_drop_rate` | 0–1 | [`RadioModel::exchange_drop_probability`] |
//! | `radio.nlos_extra_sigma_m` | m | [`RadioModel::nlos_extra_sigma_m`] |
//! | `radio.anchor_bias_m` | `[min, max]` m | [`RadioModel::anchor_bias_m`]: the bias of an anchor the profile does not list, drawn by its id |
//! | `anchors."ID".offset_m` | `[east, north]` m | where anchor ID really stands minus where the scenario says |
//! | `anchors."ID".range_bias_m` | m | [`crate::WorldAnchor::range_bias_m`] |
//! | `odometry.scale` | — | [`SensorErrors::odometry_scale`] |
//! | `imu.yaw_bias_deg` | ° | [`SensorErrors::yaw_bias_deg`] |
//! | `imu.yaw_drift_deg_per_min` | °/min | [`SensorErrors::yaw_drift_deg_per_min`] |
//! | `gnss.sigma_m` | m | [`crate::GnssModel::sigma_m`] |
//! | `gnss.correlation_s` | s | [`crate::GnssModel::correlation_s`] |
//! | `estimator.uwb_correction_clamp_m` | m | [`SimConfig::uwb_step_clamp_m`]: a firmware build with another compile-time clamp (unset: the firmware's 0.2 m) |

use std::collections::BTreeMap;
use std::fmt::Write as _;

use car_link::FirmwareVersion;
use scenarios::geometry::Point;
use serde::Deserialize;
use sha2::{Digest, Sha256};
use thiserror::Error;

use crate::{GnssModel, RadioModel, SensorErrors, SimConfig};

/// The `format` of a car profile.
pub const PROFILE_FORMAT: &str = "drivecheck-car-profile";
/// The version of the profile format this build writes and reads.
pub const PROFILE_VERSION: u32 = 1;

/// What a simulated car is like (see the module doc).
#[derive(Debug, Clone, PartialEq)]
pub struct CarProfile {
    /// The firmware version.
    pub firmware: FirmwareVersion,
    /// The UWB radio.
    pub radio: RadioProfile,
    /// Anchors that do not stand where the scenario says or have a known bias, by id.
    pub anchors: BTreeMap<u8, AnchorProfile>,
    /// The odometry.
    pub odometry: OdometryProfile,
    /// The IMU.
    pub imu: ImuProfile,
    /// The GNSS (RTK) reference.
    pub gnss: GnssProfile,
    /// The firmware build's UWB estimator, where it differs from the version's.
    pub estimator: EstimatorProfile,
}

/// `[radio]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RadioProfile {
    /// Noise of one ranging exchange, m.
    pub range_sigma_m: f64,
    /// Share of exchanges lost (a request with a lost exchange is lost whole).
    pub exchange_drop_rate: f64,
    /// Extra noise of an exchange without line of sight, m.
    pub nlos_extra_sigma_m: f64,
    /// The interval the bias of an anchor the profile does not list is drawn from, by its id, m.
    pub anchor_bias_m: [f64; 2],
}

/// `[anchors."ID"]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AnchorProfile {
    /// Where it really stands minus where the scenario says, m (east, north).
    #[serde(default)]
    pub offset_m: [f64; 2],
    /// Added to every range to it, m (unset: drawn as `radio.anchor_bias_m` says).
    #[serde(default)]
    pub range_bias_m: Option<f64>,
}

/// `[odometry]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OdometryProfile {
    /// Distance really driven per distance the car counts.
    pub scale: f64,
}

/// `[imu]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ImuProfile {
    /// Constant error of the yaw the car uses, degrees (clockwise, as the firmware's yaw).
    pub yaw_bias_deg: f64,
    /// How fast that error grows, degrees per minute.
    pub yaw_drift_deg_per_min: f64,
}

/// `[gnss]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GnssProfile {
    /// Noise of the RTK reference per axis, m.
    pub sigma_m: f64,
    /// Its correlation time (first-order Gauss–Markov), s; 0 is white.
    pub correlation_s: f64,
}

/// `[estimator]`: compile-time constants of the car's firmware build (a build with other
/// constants is another car, though its version is the same).
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EstimatorProfile {
    /// The UWB estimator's largest correction per range, m (unset: the firmware's
    /// [`car_link::firmware::UWB_CORRECTION_CLAMP_M`]).
    pub uwb_correction_clamp_m: Option<f64>,
}

impl Default for RadioProfile {
    fn default() -> Self {
        let radio = RadioModel::default();
        Self {
            range_sigma_m: radio.exchange_sigma_m,
            exchange_drop_rate: radio.exchange_drop_probability,
            nlos_extra_sigma_m: radio.nlos_extra_sigma_m,
            anchor_bias_m: [radio.anchor_bias_m.0, radio.anchor_bias_m.1],
        }
    }
}

impl Default for OdometryProfile {
    fn default() -> Self {
        Self {
            scale: SensorErrors::default().odometry_scale,
        }
    }
}

impl Default for ImuProfile {
    fn default() -> Self {
        let sensors = SensorErrors::default();
        Self {
            yaw_bias_deg: sensors.yaw_bias_deg,
            yaw_drift_deg_per_min: sensors.yaw_drift_deg_per_min,
        }
    }
}

impl Default for GnssProfile {
    fn default() -> Self {
        let gnss = GnssModel::default();
        Self {
            sigma_m: gnss.sigma_m,
            correlation_s: gnss.correlation_s,
        }
    }
}

impl Default for CarProfile {
    /// The simulated car drivecheck has always had: firmware 10.1, the default radio, GNSS and
    /// sensors, every anchor where the scenario says.
    fn default() -> Self {
        Self {
            firmware: SimConfig::default().firmware,
            radio: RadioProfile::default(),
            anchors: BTreeMap::new(),
            odometry: OdometryProfile::default(),
            imu: ImuProfile::default(),
            gnss: GnssProfile::default(),
            estimator: EstimatorProfile::default(),
        }
    }
}

/// The file as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ProfileFile {
    format: String,
    version: u32,
    #[serde(default)]
    firmware: Option<String>,
    #[serde(default)]
    radio: RadioProfile,
    #[serde(default)]
    anchors: BTreeMap<String, AnchorProfile>,
    #[serde(default)]
    odometry: OdometryProfile,
    #[serde(default)]
    imu: ImuProfile,
    #[serde(default)]
    gnss: GnssProfile,
    #[serde(default)]
    estimator: EstimatorProfile,
}

/// A profile that cannot be read or used, with the place: the file, the line and column of a
/// syntax error, the field of a bad value.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{source_name}{}{}: {problem}", location(*.line_column), field.as_ref().map(|f| format!(": {f}")).unwrap_or_default())]
pub struct ProfileError {
    /// The file (or `bundled:default`).
    pub source_name: String,
    /// Line and column, from 1, when known.
    pub line_column: Option<(usize, usize)>,
    /// The field, as a dotted path (`radio.range_sigma_m`, `anchors."50".offset_m`).
    pub field: Option<String>,
    /// What is wrong.
    pub problem: String,
}

fn location(line_column: Option<(usize, usize)>) -> String {
    line_column
        .map(|(line, column)| format!(":{line}:{column}"))
        .unwrap_or_default()
}

impl ProfileError {
    fn field(source_name: &str, field: impl Into<String>, problem: impl Into<String>) -> Self {
        Self {
            source_name: source_name.to_string(),
            line_column: None,
            field: Some(field.into()),
            problem: problem.into(),
        }
    }
}

/// Line and column (from 1) of byte `offset` in `text`.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

/// A parameter of a profile that `drivecheck calibrate` fits: where its value goes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Target {
    /// Anchor `id`'s offset, east (0) or north (1).
    Offset(u8, usize),
    /// Anchor `id`'s range bias.
    Bias(u8),
    /// The odometry scale.
    OdometryScale,
    /// The IMU's yaw bias.
    YawBias,
    /// The radio's ranging noise.
    RangeSigma,
    /// The radio's extra noise of a range without line of sight.
    NlosSigma,
}

impl CarProfile {
    /// This profile with `values` put where their `targets` say; an anchor the profile has no
    /// entry for gets one (where it stands, with the bias the radio draws for it).
    pub fn with_values(&self, targets: &[Target], values: &[f64]) -> CarProfile {
        let radio = self.radio_model();
        let mut profile = self.clone();
        for (target, &value) in targets.iter().zip(values) {
            match *target {
                Target::Offset(id, axis) => profile.anchor_mut(id, &radio).offset_m[axis] = value,
                Target::Bias(id) => profile.anchor_mut(id, &radio).range_bias_m = Some(value),
                Target::OdometryScale => profile.odometry.scale = value,
                Target::YawBias => profile.imu.yaw_bias_deg = value,
                Target::RangeSigma => profile.radio.range_sigma_m = value,
                Target::NlosSigma => profile.radio.nlos_extra_sigma_m = value,
            }
        }
        profile
    }

    /// Anchor `id`'s entry, added (where it stands, with the bias `radio` draws for it) when the
    /// profile has none.
    fn anchor_mut(&mut self, id: u8, radio: &RadioModel) -> &mut AnchorProfile {
        self.anchors.entry(id).or_insert_with(|| AnchorProfile {
            offset_m: [0.0, 0.0],
            range_bias_m: Some(radio.drawn_bias(id)),
        })
    }

    /// Reads a profile from TOML `text`; `source_name` names it in errors.
    pub fn from_toml(text: &str, source_name: &str) -> Result<Self, ProfileError> {
        let at = |span: Option<std::ops::Range<usize>>| span.map(|s| line_column(text, s.start));
        let deserializer = toml::Deserializer::parse(text).map_err(|e| ProfileError {
            source_name: source_name.to_string(),
            line_column: at(e.span()),
            field: None,
            problem: e.message().trim().to_string(),
        })?;
        let file: ProfileFile = serde_path_to_error::deserialize(deserializer).map_err(|e| {
            let path = e.path().to_string();
            let inner = e.into_inner();
            ProfileError {
                source_name: source_name.to_string(),
                line_column: at(inner.span()),
                field: (path != ".").then_some(path),
                problem: inner.message().trim().to_string(),
            }
        })?;
        Self::build(file, source_name)
    }

    fn build(file: ProfileFile, source_name: &str) -> Result<Self, ProfileError> {
        let bad = |field: &str, problem: String| ProfileError::field(source_name, field, problem);
        if file.format != PROFILE_FORMAT {
            return Err(bad(
                "format",
                format!(
                    "{:?} is not a car profile (\"{PROFILE_FORMAT}\")",
                    file.format
                ),
            ));
        }
        if file.version != PROFILE_VERSION {
            return Err(bad(
                "version",
                format!(
                    "version {} is not read by this build (it reads {PROFILE_VERSION})",
                    file.version
                ),
            ));
        }
        let firmware = match &file.firmware {
            None => CarProfile::default().firmware,
            Some(text) => {
                crate::simulated_firmware(text).map_err(|e| bad("firmware", e.to_string()))?
            }
        };
        let mut anchors = BTreeMap::new();
        for (key, anchor) in file.anchors {
            let id: u8 = key.trim().parse().map_err(|_| {
                bad(
                    &format!("anchors.{key:?}"),
                    "an anchor is named by its UWB id, 0–255".to_string(),
                )
            })?;
            anchors.insert(id, anchor);
        }
        let profile = CarProfile {
            firmware,
            radio: file.radio,
            anchors,
            odometry: file.odometry,
            imu: file.imu,
            gnss: file.gnss,
            estimator: file.estimator,
        };
        profile.check(source_name)?;
        Ok(profile)
    }

    /// Checks every value is one a car can have; the error names the field.
    pub fn check(&self, source_name: &str) -> Result<(), ProfileError> {
        let mut problems: Vec<(String, f64, &str)> = Vec::new();
        let mut need = |field: String, value: f64, ok: bool, what: &'static str| {
            if !ok || !value.is_finite() {
                problems.push((field, value, what));
            }
        };
        let r = &self.radio;
        need(
            "radio.range_sigma_m".into(),
            r.range_sigma_m,
            r.range_sigma_m >= 0.0,
            "a standard deviation, at least 0",
        );
        need(
            "radio.exchange_drop_rate".into(),
            r.exchange_drop_rate,
            (0.0..1.0).contains(&r.exchange_drop_rate),
            "a share from 0 up to (not including) 1",
        );
        need(
            "radio.nlos_extra_sigma_m".into(),
            r.nlos_extra_sigma_m,
            r.nlos_extra_sigma_m >= 0.0,
            "a standard deviation, at least 0",
        );
        for (i, value) in r.anchor_bias_m.iter().enumerate() {
            need(
                format!("radio.anchor_bias_m[{i}]"),
                *value,
                value.abs() <= 10.0,
                "a bias within ±10 m",
            );
        }
        if r.anchor_bias_m[0] > r.anchor_bias_m[1] {
            need(
                "radio.anchor_bias_m".into(),
                r.anchor_bias_m[0],
                false,
                "[min, max] with min ≤ max",
            );
        }
        for (id, a) in &self.anchors {
            for (i, value) in a.offset_m.iter().enumerate() {
                need(
                    format!("anchors.\"{id}\".offset_m[{i}]"),
                    *value,
                    value.abs() <= 100.0,
                    "an offset within ±100 m",
                );
            }
            if let Some(bias) = a.range_bias_m {
                need(
                    format!("anchors.\"{id}\".range_bias_m"),
                    bias,
                    bias.abs() <= 10.0,
                    "a bias within ±10 m",
                );
            }
        }
        let o = self.odometry.scale;
        need(
            "odometry.scale".into(),
            o,
            (0.5..=2.0).contains(&o),
            "a scale from 0.5 to 2",
        );
        need(
            "imu.yaw_bias_deg".into(),
            self.imu.yaw_bias_deg,
            self.imu.yaw_bias_deg.abs() <= 180.0,
            "an angle within ±180°",
        );
        need(
            "imu.yaw_drift_deg_per_min".into(),
            self.imu.yaw_drift_deg_per_min,
            self.imu.yaw_drift_deg_per_min.abs() <= 60.0,
            "a drift within ±60° per minute",
        );
        need(
            "gnss.sigma_m".into(),
            self.gnss.sigma_m,
            (0.0..=10.0).contains(&self.gnss.sigma_m),
            "a standard deviation from 0 to 10 m",
        );
        need(
            "gnss.correlation_s".into(),
            self.gnss.correlation_s,
            (0.0..=3600.0).contains(&self.gnss.correlation_s),
            "a correlation time from 0 to 3600 s",
        );
        if let Some(clamp) = self.estimator.uwb_correction_clamp_m {
            need(
                "estimator.uwb_correction_clamp_m".into(),
                clamp,
                clamp > 0.0 && clamp <= 10.0,
                "a correction clamp above 0 and at most 10 m",
            );
        }
        match problems.into_iter().next() {
            None => Ok(()),
            Some((field, value, what)) => Err(ProfileError::field(
                source_name,
                field,
                format!("{value} is not {what}"),
            )),
        }
    }

    /// The canonical TOML: every field, in a fixed order, numbers in their shortest exact form.
    pub fn to_toml(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(out, "format = \"{PROFILE_FORMAT}\"");
        let _ = writeln!(out, "version = {PROFILE_VERSION}");
        let _ = writeln!(out, "firmware = \"{}\"", self.firmware);
        let r = &self.radio;
        let _ = writeln!(out, "\n[radio]");
        let _ = writeln!(out, "range_sigma_m = {}", num(r.range_sigma_m));
        let _ = writeln!(out, "exchange_drop_rate = {}", num(r.exchange_drop_rate));
        let _ = writeln!(out, "nlos_extra_sigma_m = {}", num(r.nlos_extra_sigma_m));
        let _ = writeln!(
            out,
            "anchor_bias_m = [{}, {}]",
            num(r.anchor_bias_m[0]),
            num(r.anchor_bias_m[1])
        );
        for (id, a) in &self.anchors {
            let _ = writeln!(out, "\n[anchors.\"{id}\"]");
            let _ = writeln!(
                out,
                "offset_m = [{}, {}]",
                num(a.offset_m[0]),
                num(a.offset_m[1])
            );
            if let Some(bias) = a.range_bias_m {
                let _ = writeln!(out, "range_bias_m = {}", num(bias));
            }
        }
        let _ = writeln!(out, "\n[odometry]\nscale = {}", num(self.odometry.scale));
        let _ = writeln!(
            out,
            "\n[imu]\nyaw_bias_deg = {}\nyaw_drift_deg_per_min = {}",
            num(self.imu.yaw_bias_deg),
            num(self.imu.yaw_drift_deg_per_min)
        );
        let _ = writeln!(
            out,
            "\n[gnss]\nsigma_m = {}\ncorrelation_s = {}",
            num(self.gnss.sigma_m),
            num(self.gnss.correlation_s)
        );
        // Written only when set, so that the profiles written before it keep their hash.
        if let Some(clamp) = self.estimator.uwb_correction_clamp_m {
            let _ = writeln!(
                out,
                "\n[estimator]\nuwb_correction_clamp_m = {}",
                num(clamp)
            );
        }
        out
    }

    /// A content hash: the lowercase hex SHA-256 of [`CarProfile::to_toml`].
    pub fn hash(&self) -> String {
        Sha256::digest(self.to_toml().as_bytes())
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect()
    }

    /// The radio of this car (the default radio with the profile's `[radio]`).
    pub fn radio_model(&self) -> RadioModel {
        RadioModel {
            exchange_sigma_m: self.radio.range_sigma_m,
            exchange_drop_probability: self.radio.exchange_drop_rate,
            nlos_extra_sigma_m: self.radio.nlos_extra_sigma_m,
            anchor_bias_m: (self.radio.anchor_bias_m[0], self.radio.anchor_bias_m[1]),
            ..RadioModel::default()
        }
    }

    /// Makes `config` (a scenario's simulated car) this car: its firmware, radio, GNSS,
    /// sensors and estimator, and its anchors moved and biased as listed. An anchor the scenario does not have
    /// is an error (a profile of another area, or a typo).
    pub fn apply(&self, config: &mut SimConfig, source_name: &str) -> Result<(), ProfileError> {
        config.firmware = self.firmware;
        config.radio = RadioModel {
            antenna_height_m: config.radio.antenna_height_m,
            max_range_m: config.radio.max_range_m,
            anchor_bias_seed: config.radio.anchor_bias_seed,
            ..self.radio_model()
        };
        config.uwb_step_clamp_m = self.estimator.uwb_correction_clamp_m.map(|m| m as f32);
        config.gnss.sigma_m = self.gnss.sigma_m;
        config.gnss.correlation_s = self.gnss.correlation_s;
        config.sensors = SensorErrors {
            odometry_scale: self.odometry.scale,
            yaw_bias_deg: self.imu.yaw_bias_deg,
            yaw_drift_deg_per_min: self.imu.yaw_drift_deg_per_min,
        };
        for (id, profile) in &self.anchors {
            let Some(anchor) = config.world.anchors.iter_mut().find(|a| a.id == *id) else {
                let ids: Vec<String> = config
                    .world
                    .anchors
                    .iter()
                    .map(|a| a.id.to_string())
                    .collect();
                return Err(ProfileError::field(
                    source_name,
                    format!("anchors.\"{id}\""),
                    format!(
                        "the scenario has no anchor {id} (its anchors: {})",
                        ids.join(", ")
                    ),
                ));
            };
            anchor.position =
                anchor.position + Point::new(profile.offset_m[0], profile.offset_m[1]);
            if profile.range_bias_m.is_some() {
                anchor.range_bias_m = profile.range_bias_m;
            }
        }
        Ok(())
    }
}

/// A number as TOML writes it: the shortest form that reads back the same, always with a point
/// or exponent (so that it stays a float).
fn num(value: f64) -> String {
    let text = format!("{value:?}");
    if text.contains(['.', 'e', 'E', 'N', 'i']) {
        text
    } else {
        format!("{text}.0")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_go_where_their_targets_say_and_a_new_anchor_keeps_its_drawn_bias() {
        let start = CarProfile::default();
        let targets = [
            Target::Offset(7, 1),
            Target::OdometryScale,
            Target::RangeSigma,
        ];
        let fitted = start.with_values(&targets, &[0.3, 1.02, 0.07]);
        let anchor = fitted.anchors[&7];
        assert_eq!(anchor.offset_m, [0.0, 0.3]);
        assert_eq!(anchor.range_bias_m, Some(start.radio_model().drawn_bias(7)));
        assert_eq!(fitted.odometry.scale, 1.02);
        assert_eq!(fitted.radio.range_sigma_m, 0.07);
        assert_eq!(fitted.imu, start.imu);
    }

    const EXAMPLE: &str = r#"
format = "drivecheck-car-profile"
version = 1
firmware = "10.1"
[radio]
range_sigma_m = 0.05          # noise of one ranging exchange
exchange_drop_rate = 0.05     # share of exchanges lost
nlos_extra_sigma_m = 0.3
[anchors."50"]
offset_m = [0.2, -0.1]
range_bias_m = 0.08
[odometry]
scale = 1.0
[imu]
yaw_bias_deg = 0.0
yaw_drift_deg_per_min = 0.0
[gnss]
sigma_m = 0.01
correlation_s = 0.6
"#;

    #[test]
    fn the_issue_example_reads_and_its_canonical_form_reads_back_the_same() {
        let profile = CarProfile::from_toml(EXAMPLE, "car.toml").unwrap();
        assert_eq!(profile.radio.range_sigma_m, 0.05);
        assert_eq!(profile.anchors[&50].offset_m, [0.2, -0.1]);
        assert_eq!(profile.anchors[&50].range_bias_m, Some(0.08));
        assert_eq!(profile.gnss.correlation_s, 0.6);
        let again = CarProfile::from_toml(&profile.to_toml(), "again").unwrap();
        assert_eq!(again, profile);
        assert_eq!(again.hash(), profile.hash());
    }

    #[test]
    fn the_documented_default_profile_is_the_default_car_in_canonical_form() {
        let text = include_str!("../../docs/car-profile-default.toml");
        assert_eq!(text, CarProfile::default().to_toml());
    }

    #[test]
    fn what_a_file_leaves_out_is_the_default_car() {
        let text = "format = \"drivecheck-car-profile\"\nversion = 1\n";
        let profile = CarProfile::from_toml(text, "min.toml").unwrap();
        assert_eq!(profile, CarProfile::default());
        let mut config = SimConfig::default();
        let before = config.clone();
        profile.apply(&mut config, "min.toml").unwrap();
        assert_eq!(
            config, before,
            "the default profile is the default simulated car"
        );
    }

    #[test]
    fn errors_name_the_file_the_place_and_the_field() {
        let cases = [
            (
                "format = \"drivecheck-car-profile\"\nversion = 1\n[radio]\nrange_sigma = 0.1\n",
                "car.toml:4:1: radio.range_sigma: unknown field `range_sigma`",
            ),
            (
                "format = \"drivecheck-car-profile\"\nversion = 1\n[radio]\nexchange_drop_rate = 1.5\n",
                "car.toml: radio.exchange_drop_rate: 1.5 is not a share from 0 up to (not including) 1",
            ),
            (
                "format = \"drivecheck-car-profile\"\nversion = 1\n[anchors.x]\noffset_m = [0.0, 0.0]\n",
                "car.toml: anchors.\"x\": an anchor is named by its UWB id, 0–255",
            ),
            (
                "format = \"drivecheck-car-profile\"\nversion = 1\nfirmware = \"11.0\"\n",
                "car.toml: firmware: unsupported firmware \"11.0\": the simulator is 10.1 or 12.3",
            ),
            (
                "format = \"drivecheck-scenario\"\nversion = 1\n",
                "car.toml: format: \"drivecheck-scenario\" is not a car profile (\"drivecheck-car-profile\")",
            ),
            ("format = [", "car.toml:1:11: "),
            (
                "format = \"drivecheck-car-profile\"\nversion = 1\n[estimator]\nuwb_correction_clamp_m = 0.0\n",
                "car.toml: estimator.uwb_correction_clamp_m: 0 is not a correction clamp above 0 and at most 10 m",
            ),
        ];
        for (text, expected) in cases {
            let error = CarProfile::from_toml(text, "car.toml")
                .unwrap_err()
                .to_string();
            assert!(error.starts_with(expected), "{error}\nexpected {expected}");
        }
    }

    #[test]
    fn apply_moves_and_biases_the_listed_anchors_and_refuses_an_unknown_one() {
        let profile = CarProfile::from_toml(EXAMPLE, "car.toml").unwrap();
        let mut config = SimConfig::default();
        config.world.anchors.push(crate::WorldAnchor {
            id: 50,
            position: Point::new(10.0, 5.0),
            height: 2.0,
            range_bias_m: None,
        });
        profile.apply(&mut config, "car.toml").unwrap();
        let a = config.world.anchors[0];
        assert!((a.position.x - 10.2).abs() < 1e-12 && (a.position.y - 4.9).abs() < 1e-12);
        assert_eq!(a.range_bias_m, Some(0.08));
        assert_eq!(config.radio.exchange_drop_probability, 0.05);
        assert_eq!(config.gnss.correlation_s, 0.6);
        let mut other = SimConfig::default();
        let error = profile
            .apply(&mut other, "car.toml")
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("anchors.\"50\": the scenario has no anchor 50"),
            "{error}"
        );
    }

    #[test]
    fn a_firmware_build_with_another_correction_clamp_is_written_only_when_set() {
        let default_hash = CarProfile::default().hash();
        let text = "format = \"drivecheck-car-profile\"\nversion = 1\n[estimator]\n\
                    uwb_correction_clamp_m = 0.5\n";
        let profile = CarProfile::from_toml(text, "clamp.toml").unwrap();
        assert_eq!(profile.estimator.uwb_correction_clamp_m, Some(0.5));
        assert!(
            profile
                .to_toml()
                .ends_with("[estimator]\nuwb_correction_clamp_m = 0.5\n")
        );
        assert_ne!(profile.hash(), default_hash);
        assert!(!CarProfile::default().to_toml().contains("estimator"));
        assert_eq!(
            CarProfile::from_toml(&profile.to_toml(), "again").unwrap(),
            profile
        );
        let mut config = SimConfig::default();
        profile.apply(&mut config, "clamp.toml").unwrap();
        assert_eq!(config.uwb_step_clamp_m, Some(0.5));
        CarProfile::default().apply(&mut config, "default").unwrap();
        assert_eq!(
            config.uwb_step_clamp_m, None,
            "the firmware's own clamp again"
        );
    }
}
