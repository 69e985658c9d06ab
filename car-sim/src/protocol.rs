//! The firmware's packet handler: decodes a request payload with `car-link`, runs it on the
//! [`SimCar`] and encodes the replies the firmware would send (`docs/protocol.md`).

use std::time::Duration;

use bytes::Bytes;
use car_link::config::{ConfigField, ConfigValue, MainConfig};
use car_link::firmware::FirmwareVersion;
use car_link::message::{
    CarState, Dialect, EnuRef, ID_ALL, ID_CAR_CLIENT, RcMode as LinkRcMode, Reply, Request,
    RoutePart as LinkRoutePart, RoutePoint as LinkRoutePoint,
};
use car_link::version::CommandId;

use crate::autopilot::RoutePoint;
use crate::car::{RcMode, SimCar, StateReport};
use crate::config::{ApTimeMode, FirmwareConfig};

/// SET_MAIN_CONFIG acks only after the flash write; the simulator waits this long.
pub const FLASH_WRITE_DELAY: Duration = Duration::from_millis(60);

/// A reply payload and how long after the request the firmware sends it.
#[derive(Debug, Clone, PartialEq)]
pub struct Outgoing {
    /// The payload `[id][cmd][data]`, not framed.
    pub payload: Bytes,
    /// Delay after the request (zero for everything but the SET_MAIN_CONFIG ack).
    pub delay: Duration,
}

/// The simulated controller board: the car model plus its stored configuration record.
#[derive(Debug, Clone)]
pub struct Board {
    car: SimCar,
    record: MainConfig,
    version: FirmwareVersion,
}

impl Board {
    /// A board around a freshly built car.
    pub fn new(car: SimCar) -> Self {
        let version = car.firmware();
        let record = default_record(version, car.car_id());
        let mut board = Self {
            car,
            record,
            version,
        };
        let config = firmware_config_from(&board.record, board.car.firmware());
        board.car.set_config(config);
        board
    }

    /// The car model.
    pub fn car(&self) -> &SimCar {
        &self.car
    }

    /// The car model, mutable (for stepping and tests).
    pub fn car_mut(&mut self) -> &mut SimCar {
        &mut self.car
    }

    fn dialect(&self) -> Dialect {
        Dialect::firmware(self.version)
    }

    /// Handles one received payload; returns the replies in sending order. Payloads for other
    /// ids, RTCM streams, malformed data, EMERGENCY_STOP and HEARTBEAT produce nothing.
    pub fn handle(&mut self, payload: &[u8]) -> Vec<Outgoing> {
        let Ok((id, request)) = Request::decode(payload, self.version) else {
            return Vec::new();
        };
        let own = self.car.car_id();
        if id != own && id != ID_ALL && id != ID_CAR_CLIENT {
            return Vec::new();
        }
        let reply_id = if id == ID_CAR_CLIENT {
            ID_CAR_CLIENT
        } else {
            own
        };
        let replies = self.run(request);
        replies
            .into_iter()
            .filter_map(|(reply, delay)| {
                // PRINTF always carries the car's own id (which `set_id` may just have changed).
                let rid = match reply {
                    Reply::Printf(_) => self.car.car_id(),
                    _ => reply_id,
                };
                let payload = reply.encode(rid, self.dialect()).ok()?;
                Some(Outgoing { payload, delay })
            })
            .collect()
    }

    fn run(&mut self, request: Request) -> Vec<(Reply, Duration)> {
        let now = Duration::ZERO;
        let ack = |c: CommandId| vec![(Reply::Ack(c), now)];
        match request {
            Request::GetState => {
                let s = self.car.get_state();
                vec![(Reply::State(car_state(&s, self.version)), now)]
            }
            Request::TerminalCmd(text) => self
                .car
                .terminal(&text)
                .into_iter()
                .map(|t| (Reply::Printf(t), now))
                .collect(),
            Request::SetPos(p) => {
                self.car.set_pos(p.x as f32, p.y as f32, p.yaw as f32);
                Vec::new()
            }
            Request::SetPosAck(p) => {
                self.car.set_pos(p.x as f32, p.y as f32, p.yaw as f32);
                ack(CommandId::SetPosAck)
            }
            Request::SetEnuRef(e) => {
                self.car.set_enu_ref(e.lat, e.lon, e.height);
                ack(CommandId::SetEnuRef)
            }
            Request::GetEnuRef => {
                let (lat, lon, height) = self.car.enu_ref();
                vec![(Reply::EnuRef(EnuRef { lat, lon, height }), now)]
            }
            Request::AddPoints(points) => {
                self.car.add_points(&to_points(&points));
                ack(CommandId::ApAddPoints)
            }
            Request::ReplaceRoute(points) => {
                self.car.replace_route(&to_points(&points));
                ack(CommandId::ApReplaceRoute)
            }
            Request::RemoveLastPoint => {
                self.car.remove_last_point();
                ack(CommandId::ApRemoveLastPoint)
            }
            Request::ClearPoints => {
                self.car.clear_route();
                ack(CommandId::ApClearPoints)
            }
            Request::GetRoutePart { first, num } => self
                .car
                .route_part(first, num)
                .map(|part| vec![(Reply::RoutePart(link_route_part(&part)), now)])
                .unwrap_or_default(),
            Request::SetActive { active, reset } => {
                self.car.set_active(active, reset);
                ack(CommandId::ApSetActive)
            }
            Request::SyncPoint(s) => {
                self.car.sync_point(s.point, s.time_ms, s.min_diff_ms);
                ack(CommandId::ApSyncPoint)
            }
            Request::RcControl(rc) => {
                let mode = match rc.mode {
                    LinkRcMode::Current => RcMode::Current,
                    LinkRcMode::Duty => RcMode::Duty,
                    LinkRcMode::Pid => RcMode::Speed,
                    LinkRcMode::CurrentBrake => RcMode::Brake,
                };
                self.car
                    .rc_control(mode, rc.throttle as f32, rc.steering as f32);
                Vec::new()
            }
            Request::SetServoDirect(pos) => {
                self.car.set_servo_direct(pos as f32);
                Vec::new()
            }
            Request::SetYawOffset(off) => {
                self.car.set_yaw_offset(off as f32);
                Vec::new()
            }
            Request::SetYawOffsetAck(off) => {
                self.car.set_yaw_offset(off as f32);
                ack(CommandId::SetYawOffsetAck)
            }
            Request::SetMsToday(ms) => {
                self.car.set_ms_today(ms);
                Vec::new()
            }
            Request::AddUwbAnchor(a) => {
                self.car.add_anchor(a.id, a.px, a.py, a.height);
                ack(CommandId::AddUwbAnchor)
            }
            Request::ClearUwbAnchors => {
                self.car.clear_anchors();
                ack(CommandId::ClearUwbAnchors)
            }
            Request::SetMainConfig(record) => self.set_main_config(record),
            Request::GetMainConfig => {
                self.car.note_watchdog_reset();
                let config = self.record.clone();
                vec![(
                    Reply::MainConfig {
                        default: false,
                        config,
                    },
                    now,
                )]
            }
            Request::GetMainConfigDefault => {
                self.car.note_watchdog_reset();
                let config = default_record(self.version, self.car.car_id());
                vec![(
                    Reply::MainConfig {
                        default: true,
                        config,
                    },
                    now,
                )]
            }
            Request::SendRtcmUsb(_) | Request::EmergencyStop | Request::Heartbeat => Vec::new(),
            Request::Other { code, .. } => {
                if CommandId::from_code(code, self.version).is_some_and(CommandId::resets_watchdog)
                {
                    self.car.note_watchdog_reset();
                }
                Vec::new()
            }
        }
    }

    fn set_main_config(&mut self, record: MainConfig) -> Vec<(Reply, Duration)> {
        if record.version() != self.version {
            return Vec::new();
        }
        if let Some(why) = refused(&record) {
            // Not written and not acked: the host's write times out, and the line says why.
            return vec![(
                Reply::Printf(format!("SET_MAIN_CONFIG refused: {why}\n")),
                Duration::ZERO,
            )];
        }
        let config = firmware_config_from(&record, self.car.firmware());
        self.record = record;
        self.car.set_config(config);
        vec![(Reply::Ack(CommandId::SetMainConfig), FLASH_WRITE_DELAY)]
    }
}

/// Why the simulated board refuses a main-configuration record, if it does: a real field that is
/// not finite (the wire's f32auto reaches ±∞), or a size the drive train divides by — gear
/// ratio, wheel diameter, motor poles, axis distance — that is not positive, or a negative
/// autopilot top speed. The firmware writes such a record to flash and then computes with it
/// (NaN motor commands, a car that cannot be driven); the simulator refuses it instead, so that
/// a hostile or mistaken host never stops the simulation (`docs/firmware.md#hostile-configuration-values`).
/// Every other value is taken as the firmware takes it, and limited as the firmware limits it
/// ([`crate::config::truncate`]).
pub fn refused(record: &MainConfig) -> Option<String> {
    let positive = [
        ConfigField::GearRatio,
        ConfigField::WheelDiam,
        ConfigField::MotorPoles,
        ConfigField::AxisDistance,
    ];
    record.fields().into_iter().find_map(|field| {
        let value = record.get_f32(field).ok()?;
        if !value.is_finite() {
            Some(format!("{field:?} = {value}, not a finite number"))
        } else if positive.contains(&field) && value <= 0.0 {
            Some(format!("{field:?} = {value}, must be positive"))
        } else if field == ConfigField::ApMaxSpeed && value < 0.0 {
            Some(format!("{field:?} = {value}, must not be negative"))
        } else {
            None
        }
    })
}

/// The record a HIL board reports at boot: the factory defaults with `simulate_motor` on.
fn default_record(version: FirmwareVersion, car_id: u8) -> MainConfig {
    let mut record = MainConfig::factory_default(version, car_id);
    // The field exists in every version; a failure would leave the default, never panic.
    let _ = record.set(ConfigField::SimulateMotor, ConfigValue::U8(1));
    record
}

/// The model's configuration from a record; fields absent in the version keep the defaults.
pub fn firmware_config_from(record: &MainConfig, firmware: FirmwareVersion) -> FirmwareConfig {
    let mut c = FirmwareConfig::defaults(firmware);
    let flag = |f: ConfigField, d: bool| record.get_u8(f).map_or(d, |v| v != 0);
    let real = |f: ConfigField, d: f32| record.get_f32(f).unwrap_or(d);
    c.ap_repeat_routes = flag(ConfigField::ApRepeatRoutes, c.ap_repeat_routes);
    c.ap_base_rad = real(ConfigField::ApBaseRad, c.ap_base_rad);
    c.ap_rad_time_ahead = real(ConfigField::ApRadTimeAhead, c.ap_rad_time_ahead);
    c.ap_mode_time = record
        .get_u8(ConfigField::ApModeTime)
        .map_or(c.ap_mode_time, ApTimeMode::from_byte);
    c.ap_max_speed = real(ConfigField::ApMaxSpeed, c.ap_max_speed);
    if let Ok(ConfigValue::I32(v)) = record.get(ConfigField::ApTimeAddRepeatMs) {
        c.ap_time_add_repeat_ms = v;
    }
    c.uwb_max_corr = real(ConfigField::UwbMaxCorr, c.uwb_max_corr);
    c.gps_comp = flag(ConfigField::GpsComp, c.gps_comp);
    c.gps_req_rtk = flag(ConfigField::GpsReqRtk, c.gps_req_rtk);
    c.gps_use_rtcm_base_as_enu_ref = flag(
        ConfigField::GpsUseRtcmBaseAsEnuRef,
        c.gps_use_rtcm_base_as_enu_ref,
    );
    c.gps_corr_gain_stat = real(ConfigField::GpsCorrGainStat, c.gps_corr_gain_stat);
    c.gps_corr_gain_dyn = real(ConfigField::GpsCorrGainDyn, c.gps_corr_gain_dyn);
    c.gps_corr_gain_yaw = real(ConfigField::GpsCorrGainYaw, c.gps_corr_gain_yaw);
    c.gps_use_ubx_info = flag(ConfigField::GpsUseUbxInfo, c.gps_use_ubx_info);
    c.gps_ubx_max_acc = real(ConfigField::GpsUbxMaxAcc, c.gps_ubx_max_acc);
    c.gps_ant_x = real(ConfigField::GpsAntX, c.gps_ant_x);
    c.gps_ant_y = real(ConfigField::GpsAntY, c.gps_ant_y);
    c.simulate_motor = flag(ConfigField::SimulateMotor, c.simulate_motor);
    let v = &mut c.vehicle;
    v.yaw_use_odometry = flag(ConfigField::YawUseOdometry, v.yaw_use_odometry);
    v.yaw_imu_gain = real(ConfigField::YawImuGain, v.yaw_imu_gain);
    v.disable_motor = flag(ConfigField::DisableMotor, v.disable_motor);
    v.clamp_imu_yaw_stationary = flag(
        ConfigField::ClampImuYawStationary,
        v.clamp_imu_yaw_stationary,
    );
    v.use_uwb_pos = flag(ConfigField::UseUwbPos, v.use_uwb_pos);
    v.gear_ratio = real(ConfigField::GearRatio, v.gear_ratio);
    v.wheel_diam = real(ConfigField::WheelDiam, v.wheel_diam);
    v.motor_poles = real(ConfigField::MotorPoles, v.motor_poles);
    v.steering_max_angle_rad = real(ConfigField::SteeringMaxAngleRad, v.steering_max_angle_rad);
    v.steering_center = real(ConfigField::SteeringCenter, v.steering_center);
    v.steering_range = real(ConfigField::SteeringRange, v.steering_range);
    v.steering_ramp_time = real(ConfigField::SteeringRampTime, v.steering_ramp_time);
    v.axis_distance = real(ConfigField::AxisDistance, v.axis_distance);
    c
}

fn to_points(points: &[LinkRoutePoint]) -> Vec<RoutePoint> {
    points
        .iter()
        .map(|p| RoutePoint {
            px: p.px as f32,
            py: p.py as f32,
            pz: p.pz as f32,
            speed: p.speed as f32,
            time: p.time_ms,
            attributes: p.attributes,
        })
        .collect()
}

fn link_route_part(part: &crate::autopilot::RoutePart) -> LinkRoutePart {
    LinkRoutePart {
        route_len: part.route_len,
        points: part
            .points
            .iter()
            .map(|p| LinkRoutePoint {
                px: f64::from(p.px),
                py: f64::from(p.py),
                pz: f64::from(p.pz),
                speed: f64::from(p.speed),
                time_ms: p.time,
                attributes: p.attributes,
            })
            .collect(),
    }
}

/// The GET_STATE record of the wire from the model's report.
pub fn car_state(s: &StateReport, version: FirmwareVersion) -> CarState {
    let f = f64::from;
    let triple = |t: [f32; 3]| [f(t[0]), f(t[1]), f(t[2])];
    CarState {
        version,
        roll: f(s.roll),
        pitch: f(s.pitch),
        yaw: f(s.yaw),
        accel: triple(s.accel),
        gyro: triple(s.gyro),
        mag: triple(s.mag),
        px: f(s.px),
        py: f(s.py),
        speed: f(s.speed),
        v_in: f(s.v_in),
        temp_mos: f(s.temp_mos),
        mc_fault: s.mc_fault,
        px_gps: f(s.px_gps),
        py_gps: f(s.py_gps),
        ap_goal_px: f(s.ap_goal_px),
        ap_goal_py: f(s.ap_goal_py),
        ap_rad: f(s.ap_rad),
        ms_today: s.ms_today,
        ap_route_left: s.ap_route_left,
        px_uwb: f(s.px_uwb),
        py_uwb: f(s.py_uwb),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::car::CarOptions;
    use car_link::message::Request;

    /// The factory record of `version` with the wheel diameter's four bytes set to `bits`.
    fn with_wheel_diameter_bits(version: FirmwareVersion, bits: u32) -> MainConfig {
        let default = MainConfig::factory_default(version, 1);
        let mut marked = default.clone();
        marked
            .set(ConfigField::WheelDiam, ConfigValue::F32(123.25))
            .expect("the field exists");
        let at = (0..default.record().len())
            .find(|&i| default.record()[i] != marked.record()[i])
            .expect("the field moved");
        let mut bytes = default.record().to_vec();
        bytes[at..at + 4].copy_from_slice(&bits.to_be_bytes());
        MainConfig::from_record(version, bytes).expect("the layout is kept")
    }

    #[test]
    fn a_record_with_an_infinite_or_zero_size_is_refused_and_the_old_one_kept() {
        for version in FirmwareVersion::SIMULATED {
            let mut board = Board::new(SimCar::new(CarOptions {
                firmware: version,
                ..CarOptions::default()
            }));
            let before = board.record.clone();
            for (bits, why) in [
                (0x7F80_0000, "WheelDiam = inf, not a finite number"),
                (0, "WheelDiam = 0, must be positive"),
            ] {
                let record = with_wheel_diameter_bits(version, bits);
                let replies = board.run(Request::SetMainConfig(record));
                assert_eq!(
                    replies,
                    [(
                        Reply::Printf(format!("SET_MAIN_CONFIG refused: {why}\n")),
                        Duration::ZERO
                    )]
                );
                assert_eq!(board.record, before);
            }
            // An ordinary record is written and acked.
            let mut record = before.clone();
            record
                .set(ConfigField::WheelDiam, ConfigValue::F32(0.12))
                .expect("the field exists");
            let replies = board.run(Request::SetMainConfig(record.clone()));
            assert_eq!(
                replies,
                [(Reply::Ack(CommandId::SetMainConfig), FLASH_WRITE_DELAY)]
            );
            assert_eq!(board.record, record);
        }
    }
}
