//! The main-configuration record (`docs/protocol.md#main-configuration`): positional, version-specific, with a
//! NUL-terminated log name in the middle. Kept as the raw record so that a read-modify-write sends back every byte it
//! did not change.

use std::fmt;

use thiserror::Error;

use crate::encoding::{f32auto_decode, f32auto_encode};
use crate::firmware::FirmwareVersion;

/// The longest log name the firmware stores (without its NUL).
pub const MAX_LOG_NAME: usize = 20;

/// A named field of the main-configuration record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[allow(missing_docs)] // the names are the firmware's own; see `docs/protocol.md#main-configuration`
pub enum ConfigField {
    MagUse,
    MagComp,
    YawMagGain,
    MagCalCx,
    MagCalCy,
    MagCalCz,
    MagCalXx,
    MagCalXy,
    MagCalXz,
    MagCalYx,
    MagCalYy,
    MagCalYz,
    MagCalZx,
    MagCalZy,
    MagCalZz,
    GpsAntX,
    GpsAntY,
    GpsComp,
    GpsReqRtk,
    GpsUseRtcmBaseAsEnuRef,
    GpsCorrGainStat,
    GpsCorrGainDyn,
    GpsCorrGainYaw,
    GpsSendNmea,
    GpsUseUbxInfo,
    GpsUbxMaxAcc,
    UwbMaxCorr,
    ApRepeatRoutes,
    ApBaseRad,
    ApRadTimeAhead,
    ApModeTime,
    ApMaxSpeed,
    ApTimeAddRepeatMs,
    LogRateHz,
    LogEn,
    LogName,
    LogModeExt,
    LogUartBaud,
    YawUseOdometry,
    YawImuGain,
    DisableMotor,
    SimulateMotor,
    ClampImuYawStationary,
    UseUwbPos,
    GearRatio,
    WheelDiam,
    MotorPoles,
    SteeringMaxAngleRad,
    SteeringCenter,
    SteeringRange,
    SteeringRampTime,
    AxisDistance,
}

/// How a field is stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    U8,
    I16,
    I32,
    U32,
    F32Auto,
    Text,
}

impl Kind {
    fn fixed_size(self) -> Option<usize> {
        match self {
            Kind::U8 => Some(1),
            Kind::I16 => Some(2),
            Kind::I32 | Kind::U32 | Kind::F32Auto => Some(4),
            Kind::Text => None,
        }
    }
}

/// A field's value.
#[derive(Debug, Clone, PartialEq)]
pub enum ConfigValue {
    /// A byte or boolean.
    U8(u8),
    /// A 16-bit integer.
    I16(i16),
    /// A 32-bit integer.
    I32(i32),
    /// An unsigned 32-bit integer.
    U32(u32),
    /// An `f32auto` number.
    F32(f32),
    /// The log name.
    Text(String),
}

/// A field that cannot be read or written.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ConfigError {
    /// The field does not exist in this firmware version.
    #[error("field {field:?} does not exist in firmware {version}")]
    Absent {
        /// The field.
        field: ConfigField,
        /// The record's version.
        version: FirmwareVersion,
    },
    /// The record ends before the field.
    #[error("record of {len} bytes ends inside field {field:?} at data offset {offset}")]
    Truncated {
        /// The field.
        field: ConfigField,
        /// Its data offset.
        offset: usize,
        /// The record's length.
        len: usize,
    },
    /// The log name has no NUL terminator within 21 bytes.
    #[error("log name at data offset {offset} has no NUL terminator")]
    Unterminated {
        /// Data offset of the name.
        offset: usize,
    },
    /// The value has the wrong type for the field, or does not fit it.
    #[error("value {value:?} does not fit field {field:?}")]
    BadValue {
        /// The field.
        field: ConfigField,
        /// The value given.
        value: ConfigValue,
    },
}

fn layout(version: FirmwareVersion) -> Vec<(ConfigField, Kind)> {
    use ConfigField::*;
    use Kind::*;
    let mut fields = vec![(MagUse, U8), (MagComp, U8), (YawMagGain, F32Auto)];
    for f in [
        MagCalCx, MagCalCy, MagCalCz, MagCalXx, MagCalXy, MagCalXz, MagCalYx, MagCalYy, MagCalYz,
    ] {
        fields.push((f, F32Auto));
    }
    for f in [MagCalZx, MagCalZy, MagCalZz, GpsAntX, GpsAntY] {
        fields.push((f, F32Auto));
    }
    fields.extend([(GpsComp, U8), (GpsReqRtk, U8), (GpsUseRtcmBaseAsEnuRef, U8)]);
    fields.extend([
        (GpsCorrGainStat, F32Auto),
        (GpsCorrGainDyn, F32Auto),
        (GpsCorrGainYaw, F32Auto),
    ]);
    fields.extend([
        (GpsSendNmea, U8),
        (GpsUseUbxInfo, U8),
        (GpsUbxMaxAcc, F32Auto),
    ]);
    if version >= FirmwareVersion::new(12, 2) {
        fields.push((UwbMaxCorr, F32Auto));
    }
    fields.extend([(ApRepeatRoutes, U8), (ApBaseRad, F32Auto)]);
    if version >= FirmwareVersion::V12_0 {
        fields.push((ApRadTimeAhead, F32Auto));
    }
    fields.extend([
        (ApModeTime, U8),
        (ApMaxSpeed, F32Auto),
        (ApTimeAddRepeatMs, I32),
    ]);
    fields.extend([
        (LogRateHz, I16),
        (LogEn, U8),
        (LogName, Text),
        (LogModeExt, U8),
        (LogUartBaud, U32),
    ]);
    fields.extend([
        (YawUseOdometry, U8),
        (YawImuGain, F32Auto),
        (DisableMotor, U8),
        (SimulateMotor, U8),
    ]);
    if version >= FirmwareVersion::new(10, 2) {
        fields.push((ClampImuYawStationary, U8));
    }
    if version >= FirmwareVersion::V11_0 {
        fields.push((UseUwbPos, U8));
    }
    for f in [
        GearRatio,
        WheelDiam,
        MotorPoles,
        SteeringMaxAngleRad,
        SteeringCenter,
        SteeringRange,
    ] {
        fields.push((f, F32Auto));
    }
    fields.extend([(SteeringRampTime, F32Auto), (AxisDistance, F32Auto)]);
    fields
}

/// Bytes of the multirotor block that closes the record (35 `f32auto`, 7 `u8`, 2 `u16`).
pub const MULTIROTOR_BLOCK_LEN: usize = 35 * 4 + 7 + 2 * 2;

/// The factory default of a field (`docs/protocol.md#main-configuration`, `docs/firmware.md#vehicle-parameters`), per
/// version and car id.
fn factory_default(field: ConfigField, version: FirmwareVersion, car_id: u8) -> ConfigValue {
    use ConfigField::*;
    let profile = version.profile();
    let f = ConfigValue::F32;
    let u = ConfigValue::U8;
    match field {
        MagComp | GpsComp | GpsReqRtk | GpsUseRtcmBaseAsEnuRef | GpsSendNmea | GpsUseUbxInfo => {
            u(1)
        }
        ApRepeatRoutes => u(1),
        ClampImuYawStationary => u(u8::from(profile.default_clamp_imu_yaw_stationary)),
        MagUse | ApModeTime | LogEn | LogModeExt | YawUseOdometry | DisableMotor
        | SimulateMotor | UseUwbPos => u(0),
        YawMagGain => f(1.2),
        MagCalXx | MagCalYy | MagCalZz | GpsCorrGainYaw => f(1.0),
        MagCalCx | MagCalCy | MagCalCz | MagCalXy | MagCalXz | MagCalYx | MagCalYz | MagCalZx
        | MagCalZy => f(0.0),
        GpsAntX => f(if car_id == 1 { 0.42 } else { 0.0 }),
        GpsAntY => f(0.0),
        GpsCorrGainStat | GpsCorrGainDyn => f(0.05),
        GpsUbxMaxAcc => f(0.12),
        UwbMaxCorr => f(0.1),
        ApBaseRad => f(profile.default_base_radius_m as f32),
        ApRadTimeAhead => f(profile.default_radius_time_ahead_s as f32),
        ApMaxSpeed => f(30.0 / 3.6),
        ApTimeAddRepeatMs => ConfigValue::I32(60_000),
        LogRateHz => ConfigValue::I16(50),
        LogName => ConfigValue::Text("New Log".into()),
        LogUartBaud => ConfigValue::U32(115_200),
        YawImuGain => f(0.5),
        GearRatio => f((1.0 / 3.0) * (21.0 / 37.0)),
        WheelDiam => f(0.11),
        MotorPoles => f(4.0),
        SteeringMaxAngleRad => f(0.42041),
        SteeringCenter => f(if car_id == 1 {
            profile.car_1_steering_center as f32
        } else {
            0.5
        }),
        SteeringRange => f(0.58),
        SteeringRampTime => f(profile.default_steering_ramp_time_s as f32),
        AxisDistance => f(0.475),
    }
}

fn value_bytes(value: &ConfigValue) -> Vec<u8> {
    match value {
        ConfigValue::U8(v) => vec![*v],
        ConfigValue::I16(v) => v.to_be_bytes().to_vec(),
        ConfigValue::I32(v) => v.to_be_bytes().to_vec(),
        ConfigValue::U32(v) => v.to_be_bytes().to_vec(),
        ConfigValue::F32(v) => f32auto_encode("config", *v)
            .unwrap_or(0)
            .to_be_bytes()
            .to_vec(),
        ConfigValue::Text(text) => {
            let mut bytes: Vec<u8> = text
                .chars()
                .map(|c| u8::try_from(u32::from(c)).unwrap_or(b'?'))
                .collect();
            bytes.push(0);
            bytes
        }
    }
}

/// A main-configuration record of one firmware version (the data after `[id][cmd]`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MainConfig {
    version: FirmwareVersion,
    record: Vec<u8>,
}

impl MainConfig {
    /// The named fields of this record's layout (its firmware version's), in record order.
    pub fn fields(&self) -> Vec<ConfigField> {
        layout(self.version)
            .into_iter()
            .map(|(field, _)| field)
            .collect()
    }

    /// Wraps a record, checking that every named field of `version` is present.
    pub fn from_record(version: FirmwareVersion, record: Vec<u8>) -> Result<Self, ConfigError> {
        let config = MainConfig { version, record };
        config.locate(ConfigField::AxisDistance)?;
        Ok(config)
    }

    /// The factory defaults of `version` for car `car_id` (the reference gives car 1 a GNSS antenna offset and,
    /// on 10.x, another steering centre). The multirotor block, whose defaults the protocol does not give, is
    /// zero. What a simulator answers to GET_MAIN_CONFIG before any SET_MAIN_CONFIG.
    pub fn factory_default(version: FirmwareVersion, car_id: u8) -> MainConfig {
        let mut record = Vec::with_capacity(320);
        for (field, _) in layout(version) {
            record.extend(value_bytes(&factory_default(field, version, car_id)));
        }
        record.extend(std::iter::repeat_n(0, MULTIROTOR_BLOCK_LEN));
        MainConfig { version, record }
    }

    /// Whether the record is safe for a test drive (`docs/protocol.md#client-checklist`): routes not repeated, speed
    /// mode, and (11.0+) the fused position reported, not the UWB one. Returns the fields that are not, with their
    /// values.
    pub fn test_drive_deviations(&self) -> Result<Vec<(ConfigField, u8)>, ConfigError> {
        let mut deviations = Vec::new();
        for field in [
            ConfigField::ApRepeatRoutes,
            ConfigField::ApModeTime,
            ConfigField::UseUwbPos,
        ] {
            match self.get_u8(field) {
                Ok(0) | Err(ConfigError::Absent { .. }) => {}
                Ok(value) => deviations.push((field, value)),
                Err(error) => return Err(error),
            }
        }
        Ok(deviations)
    }

    /// Sets every field [`Self::test_drive_deviations`] reports to 0.
    pub fn make_test_drive_safe(&mut self) -> Result<(), ConfigError> {
        for (field, _) in self.test_drive_deviations()? {
            self.set(field, ConfigValue::U8(0))?;
        }
        Ok(())
    }

    /// The raw record, as sent in SET_MAIN_CONFIG.
    pub fn record(&self) -> &[u8] {
        &self.record
    }

    /// The firmware version whose layout the record follows.
    pub fn version(&self) -> FirmwareVersion {
        self.version
    }

    /// Data offset, kind and size of `field`.
    fn locate(&self, field: ConfigField) -> Result<(usize, Kind, usize), ConfigError> {
        let mut offset = 0;
        for (name, kind) in layout(self.version) {
            let size = match kind.fixed_size() {
                Some(size) => size,
                None => self.text_size(offset)?,
            };
            if offset + size > self.record.len() {
                return Err(ConfigError::Truncated {
                    field: name,
                    offset,
                    len: self.record.len(),
                });
            }
            if name == field {
                return Ok((offset, kind, size));
            }
            offset += size;
        }
        Err(ConfigError::Absent {
            field,
            version: self.version,
        })
    }

    /// Size of the NUL-terminated text at `offset`, NUL included.
    fn text_size(&self, offset: usize) -> Result<usize, ConfigError> {
        let rest = self.record.get(offset..).unwrap_or_default();
        rest.iter()
            .take(MAX_LOG_NAME + 1)
            .position(|&b| b == 0)
            .map(|nul| nul + 1)
            .ok_or(ConfigError::Unterminated { offset })
    }

    /// Reads a field.
    pub fn get(&self, field: ConfigField) -> Result<ConfigValue, ConfigError> {
        let (offset, kind, size) = self.locate(field)?;
        let bytes = &self.record[offset..offset + size];
        let be4 = || [bytes[0], bytes[1], bytes[2], bytes[3]];
        Ok(match kind {
            Kind::U8 => ConfigValue::U8(bytes[0]),
            Kind::I16 => ConfigValue::I16(i16::from_be_bytes([bytes[0], bytes[1]])),
            Kind::I32 => ConfigValue::I32(i32::from_be_bytes(be4())),
            Kind::U32 => ConfigValue::U32(u32::from_be_bytes(be4())),
            Kind::F32Auto => ConfigValue::F32(f32auto_decode(u32::from_be_bytes(be4()))),
            Kind::Text => {
                ConfigValue::Text(bytes[..size - 1].iter().map(|&b| char::from(b)).collect())
            }
        })
    }

    /// Reads a byte or boolean field.
    pub fn get_u8(&self, field: ConfigField) -> Result<u8, ConfigError> {
        match self.get(field)? {
            ConfigValue::U8(v) => Ok(v),
            value => Err(ConfigError::BadValue { field, value }),
        }
    }

    /// Reads an `f32auto` field.
    pub fn get_f32(&self, field: ConfigField) -> Result<f32, ConfigError> {
        match self.get(field)? {
            ConfigValue::F32(v) => Ok(v),
            value => Err(ConfigError::BadValue { field, value }),
        }
    }

    /// Writes a field, leaving every other byte of the record as it was.
    pub fn set(&mut self, field: ConfigField, value: ConfigValue) -> Result<(), ConfigError> {
        let (offset, kind, size) = self.locate(field)?;
        let bad = |value: ConfigValue| ConfigError::BadValue { field, value };
        let bytes: Vec<u8> = match (kind, &value) {
            (Kind::U8, ConfigValue::U8(v)) => vec![*v],
            (Kind::I16, ConfigValue::I16(v)) => v.to_be_bytes().to_vec(),
            (Kind::I32, ConfigValue::I32(v)) => v.to_be_bytes().to_vec(),
            (Kind::U32, ConfigValue::U32(v)) => v.to_be_bytes().to_vec(),
            (Kind::F32Auto, ConfigValue::F32(v)) => f32auto_encode("config", *v)
                .map_err(|_| bad(value.clone()))?
                .to_be_bytes()
                .to_vec(),
            (Kind::Text, ConfigValue::Text(text)) => {
                let latin1: Option<Vec<u8>> = text
                    .chars()
                    .map(|c| u8::try_from(u32::from(c)).ok())
                    .collect();
                match latin1 {
                    Some(mut b) if b.len() <= MAX_LOG_NAME && !b.contains(&0) => {
                        b.push(0);
                        b
                    }
                    _ => return Err(bad(value)),
                }
            }
            _ => return Err(bad(value)),
        };
        self.record.splice(offset..offset + size, bytes);
        Ok(())
    }
}

impl fmt::Display for MainConfig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "main config ({} bytes, firmware {})",
            self.record.len(),
            self.version
        )
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A record with the firmware defaults of `version`.
    pub(crate) fn default_record(version: FirmwareVersion) -> Vec<u8> {
        MainConfig::factory_default(version, 0).record().to_vec()
    }

    #[test]
    fn offsets_match_the_protocol_table() {
        let v122 = MainConfig::from_record(
            FirmwareVersion::new(12, 2),
            default_record(FirmwareVersion::new(12, 2)),
        );
        let v101 = MainConfig::from_record(
            FirmwareVersion::V10_1,
            default_record(FirmwareVersion::V10_1),
        );
        let (Ok(v122), Ok(v101)) = (v122, v101) else {
            panic!("default records must parse")
        };
        let at = |c: &MainConfig, f| c.locate(f).map(|(o, _, _)| o);
        assert_eq!(at(&v122, ConfigField::ApRepeatRoutes), Ok(87));
        assert_eq!(at(&v122, ConfigField::ApModeTime), Ok(96));
        assert_eq!(at(&v122, ConfigField::LogName), Ok(108));
        assert_eq!(at(&v101, ConfigField::ApRepeatRoutes), Ok(83));
        assert_eq!(at(&v101, ConfigField::ApModeTime), Ok(88));
        assert_eq!(at(&v101, ConfigField::LogName), Ok(100));
        // With the header, the whole payload is 315 bytes (12.2+) and 305 bytes (10.1).
        assert_eq!(v122.record().len() + 2, 315);
        assert_eq!(v101.record().len() + 2, 305);
        assert!(matches!(
            v101.get(ConfigField::UseUwbPos),
            Err(ConfigError::Absent { .. })
        ));
    }

    #[test]
    fn read_modify_write_keeps_other_bytes() {
        let version = FirmwareVersion::V12_3;
        let Ok(mut config) = MainConfig::from_record(version, default_record(version)) else {
            panic!("default record must parse")
        };
        assert_eq!(config.get_u8(ConfigField::ApRepeatRoutes), Ok(1));
        let before = config.record().to_vec();
        assert_eq!(
            config.set(ConfigField::ApRepeatRoutes, ConfigValue::U8(0)),
            Ok(())
        );
        assert_eq!(config.get_u8(ConfigField::ApRepeatRoutes), Ok(0));
        let changed: Vec<usize> = (0..before.len())
            .filter(|&i| before[i] != config.record()[i])
            .collect();
        assert_eq!(changed, vec![87]);
        assert_eq!(
            config.set(ConfigField::LogName, ConfigValue::Text("drivecheck".into())),
            Ok(())
        );
        assert_eq!(config.record().len(), before.len() + 3);
        assert_eq!(
            config.get(ConfigField::SimulateMotor),
            Ok(ConfigValue::U8(0))
        );
        assert_eq!(config.get_f32(ConfigField::ApBaseRad), Ok(0.8));
    }

    #[test]
    fn factory_defaults_follow_the_generation() {
        let old = MainConfig::factory_default(FirmwareVersion::V10_1, 1);
        let new = MainConfig::factory_default(FirmwareVersion::V12_3, 1);
        assert_eq!(old.get_f32(ConfigField::ApBaseRad), Ok(1.2));
        assert_eq!(new.get_f32(ConfigField::ApBaseRad), Ok(0.8));
        assert_eq!(old.get_f32(ConfigField::SteeringCenter), Ok(0.53));
        assert_eq!(new.get_f32(ConfigField::GpsAntX), Ok(0.42));
        assert_eq!(
            new.get(ConfigField::LogName),
            Ok(ConfigValue::Text("New Log".into()))
        );
        assert_eq!(
            new.get(ConfigField::ApTimeAddRepeatMs),
            Ok(ConfigValue::I32(60_000))
        );
    }

    #[test]
    fn the_factory_default_is_not_safe_for_a_test_drive() {
        let mut config = MainConfig::factory_default(FirmwareVersion::V12_3, 0);
        assert_eq!(
            config.test_drive_deviations(),
            Ok(vec![(ConfigField::ApRepeatRoutes, 1)])
        );
        assert_eq!(config.make_test_drive_safe(), Ok(()));
        assert_eq!(config.test_drive_deviations(), Ok(vec![]));
        let old = MainConfig::factory_default(FirmwareVersion::V10_1, 0);
        assert_eq!(
            old.test_drive_deviations(),
            Ok(vec![(ConfigField::ApRepeatRoutes, 1)])
        );
    }

    #[test]
    fn truncated_records_are_rejected() {
        let version = FirmwareVersion::V12_3;
        let mut record = default_record(version);
        record.truncate(120);
        assert!(matches!(
            MainConfig::from_record(version, record),
            Err(ConfigError::Truncated { .. })
        ));
        assert!(matches!(
            MainConfig::from_record(version, vec![0xAA; 200]),
            Err(ConfigError::Unterminated { offset: 108 })
        ));
    }
}
