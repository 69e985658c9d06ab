//! Typed payloads, `[id][cmd][data…]`, for both directions (`docs/protocol.md#payload-header`,
//! `docs/protocol.md#commands-drivecheck-uses`, `docs/protocol.md#state-reply`, `docs/protocol.md#route-points`).
//!
//! [`Request`] is what a host sends to the car, [`Reply`] what the car sends back. A client encodes requests and
//! decodes replies; a simulator decodes requests and encodes replies, with the same types. Layouts and ids come
//! from the [`FirmwareVersion`]; the rounding of scaled numbers from the [`Dialect`].
//!
//! The car side, as a simulator would write it (the payload is the AP_ADD_POINTS test vector to car 1, 10.x layout:
//! `docs/protocol.md#test-vectors`):
//!
//! ```
//! use car_link::message::{Dialect, Reply, Request, RoutePoint};
//! use car_link::firmware::FirmwareVersion;
//! use car_link::version::CommandId;
//!
//! let version = FirmwareVersion::V10_1;
//! let payload = [
//!     0x01, 0x37, 0x00, 0x01, 0x9A, 0x28, 0xFF, 0xFF, 0x81, 0x0C, 0x00, 0x26, 0x25, 0xA0, 0, 0, 0, 0,
//! ];
//! let (car, request) = Request::decode(&payload, version).expect("a valid request");
//! assert_eq!(request, Request::AddPoints(vec![RoutePoint::at(10.5, -3.25, 2.5)]));
//! // Replies carry the car's own id; the firmware truncates scaled values.
//! let ack = Reply::Ack(CommandId::ApAddPoints).encode(car, Dialect::firmware(version)).expect("encodes");
//! assert_eq!(&ack[..], &[0x01, 0x37]);
//! ```

use bytes::{BufMut, Bytes, BytesMut};
use thiserror::Error;

use crate::config::{ConfigError, MainConfig};
use crate::encoding::{
    NumberError, Rounding, SCALE_FINE, SCALE_HEIGHT, SCALE_LAT_LON, SCALE_POSITION, f32auto_decode,
    f32auto_encode, scaled_i32, scaled_i64, unscale_i32, unscale_i64,
};
use crate::firmware::FirmwareVersion;
use crate::frame::FIRMWARE_MAX_PAYLOAD;
use crate::version::CommandId;

/// Broadcast id (`ID_ALL`): every car processes it and replies with its own id.
pub const ID_ALL: u8 = 255;
/// "Bridge only" id (`ID_CAR_CLIENT`): the car stamps its acks and data replies to it with 254, which
/// the bridge does not forward; PRINTF replies always carry the car's own id.
pub const ID_CAR_CLIENT: u8 = 254;
/// A payload starting with this byte is taken by the firmware as an RTCM3 stream, so car id 211 is unusable.
pub const RTCM_PREAMBLE: u8 = 0xD3;
/// Most points per AP_ADD_POINTS or AP_REPLACE_ROUTE packet by convention.
pub const POINTS_PER_PACKET: usize = 5;
/// Largest `num` of AP_GET_ROUTE_PART that the firmware answers.
pub const MAX_ROUTE_PART: u8 = 20;
/// Bytes of a GET_STATE reply payload.
pub const STATE_PAYLOAD_LEN: usize = 107;

/// Which way a payload travels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Host to car: a [`Request`].
    ToCar,
    /// Car to host: a [`Reply`].
    FromCar,
}

/// How one side writes numbers: the firmware version (layouts and ids) and the rounding of scaled values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Dialect {
    /// The firmware version whose layouts and ids are used.
    pub version: FirmwareVersion,
    /// How scaled values are rounded.
    pub rounding: Rounding,
}

impl Dialect {
    /// A host (the control station's rounding: half away from zero, double precision).
    pub fn host(version: FirmwareVersion) -> Self {
        Dialect {
            version,
            rounding: Rounding::HalfAwayFromZero,
        }
    }

    /// The car firmware (truncation in single precision), for a bit-faithful simulator.
    pub fn firmware(version: FirmwareVersion) -> Self {
        Dialect {
            version,
            rounding: Rounding::FirmwareTruncate,
        }
    }
}

/// A pose for SET_POS: ENU metres and yaw in degrees (clockwise from East).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// East, m.
    pub x: f64,
    /// North, m.
    pub y: f64,
    /// Degrees, positive clockwise, 0 = East.
    pub yaw: f64,
}

/// The ENU reference (SET_ENU_REF, GET_ENU_REF).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EnuRef {
    /// Latitude, degrees.
    pub lat: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Height, m.
    pub height: f64,
}

/// A route point (`docs/protocol.md#route-points`). `pz` and `attributes` exist on the wire from 12.0 only.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RoutePoint {
    /// East, m.
    pub px: f64,
    /// North, m.
    pub py: f64,
    /// Height, m (12.x only; unused by the autopilot, dropped when sent to older firmware).
    pub pz: f64,
    /// Speed, m/s.
    pub speed: f64,
    /// ms of day or since activation (by `ap_mode_time`); 0 in speed mode.
    pub time_ms: i32,
    /// 12.x: bits 0–2 positioning source, 3–5 hydraulics. Must be 0 for older firmware.
    pub attributes: u32,
}

impl RoutePoint {
    /// A speed-mode point at (x, y).
    pub fn at(px: f64, py: f64, speed: f64) -> Self {
        RoutePoint {
            px,
            py,
            speed,
            ..RoutePoint::default()
        }
    }
}

/// RC_CONTROL modes (`docs/protocol.md#braking`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RcMode {
    /// Throttle is a motor current in A.
    Current = 0,
    /// Throttle is a duty cycle, −1..1.
    Duty = 1,
    /// Throttle is a speed in m/s.
    Pid = 2,
    /// Throttle is a brake current in A.
    CurrentBrake = 3,
}

/// RC_CONTROL data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RcControl {
    /// What the throttle means.
    pub mode: RcMode,
    /// Throttle, scaled 1e4 on the wire.
    pub throttle: f64,
    /// Steering −1..1 (+1 turns right), scaled 1e6 on the wire.
    pub steering: f64,
}

/// A UWB anchor (ADD_UWB_ANCHOR). Ids must be 0–255 for ranging to work.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Anchor {
    /// Anchor id.
    pub id: i16,
    /// East, m.
    pub px: f32,
    /// North, m.
    pub py: f32,
    /// Height, m (stored, never used by the fusion).
    pub height: f32,
}

/// AP_SYNC_POINT data (`docs/protocol.md#other-commands`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SyncPoint {
    /// Route index.
    pub point: i32,
    /// Duration in ms to reach it.
    pub time_ms: i32,
    /// Do nothing if `time_ms` is below this.
    pub min_diff_ms: i32,
}

/// The GET_STATE reply (`docs/protocol.md#state-reply`), every field. Scaled values are decoded to `f64`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CarState {
    /// Firmware version (`fw_major`, `fw_minor`).
    pub version: FirmwareVersion,
    /// Roll, degrees.
    pub roll: f64,
    /// Pitch, degrees.
    pub pitch: f64,
    /// Yaw, degrees clockwise from East (the UWB yaw when `use_uwb_pos` is set, 11.0+).
    pub yaw: f64,
    /// Acceleration x, y, z in g.
    pub accel: [f64; 3],
    /// Gyro x, y, z in rad/s.
    pub gyro: [f64; 3],
    /// Raw magnetometer x, y, z.
    pub mag: [f64; 3],
    /// Fused x, m (UWB x with `use_uwb_pos`).
    pub px: f64,
    /// Fused y, m (UWB y with `use_uwb_pos`).
    pub py: f64,
    /// Speed from motor RPM, m/s, signed.
    pub speed: f64,
    /// Input voltage, V.
    pub v_in: f64,
    /// Motor-controller FET temperature, °C.
    pub temp_mos: f64,
    /// Motor-controller fault code, 0 = none.
    pub mc_fault: u8,
    /// Last GNSS fix x, m.
    pub px_gps: f64,
    /// Last GNSS fix y, m.
    pub py_gps: f64,
    /// Pursuit goal x, m.
    pub ap_goal_px: f64,
    /// Pursuit goal y, m.
    pub ap_goal_py: f64,
    /// Look-ahead radius, m; −1 when inactive or at the route end.
    pub ap_rad: f64,
    /// ms since UTC midnight; −1 until known.
    pub ms_today: i32,
    /// Points left on the route (stale while inactive).
    pub ap_route_left: i16,
    /// UWB x, m (fused x with `use_uwb_pos`).
    pub px_uwb: f64,
    /// UWB y, m (fused y with `use_uwb_pos`).
    pub py_uwb: f64,
}

/// The AP_GET_ROUTE_PART reply.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RoutePart {
    /// The ring write index (the number of points if the ring never wrapped).
    pub route_len: i32,
    /// The points asked for; indices past `route_len` come back as zero points.
    pub points: Vec<RoutePoint>,
}

/// A host-to-car payload.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// GET_STATE.
    GetState,
    /// TERMINAL_CMD: the text, without terminator.
    TerminalCmd(String),
    /// SET_POS (no reply).
    SetPos(Pose),
    /// SET_POS_ACK (acked).
    SetPosAck(Pose),
    /// SET_ENU_REF.
    SetEnuRef(EnuRef),
    /// GET_ENU_REF.
    GetEnuRef,
    /// AP_ADD_POINTS.
    AddPoints(Vec<RoutePoint>),
    /// AP_REPLACE_ROUTE.
    ReplaceRoute(Vec<RoutePoint>),
    /// AP_REMOVE_LAST_POINT.
    RemoveLastPoint,
    /// AP_CLEAR_POINTS.
    ClearPoints,
    /// AP_GET_ROUTE_PART.
    GetRoutePart {
        /// First index.
        first: i32,
        /// How many points (no reply above 20).
        num: u8,
    },
    /// AP_SET_ACTIVE. `reset` is the 12.3 `reset_state` byte.
    SetActive {
        /// Activate or deactivate.
        active: bool,
        /// 12.3: reset the route progress.
        reset: bool,
    },
    /// AP_SYNC_POINT.
    SyncPoint(SyncPoint),
    /// RC_CONTROL (no reply).
    RcControl(RcControl),
    /// SET_SERVO_DIRECT, servo position 0..1 (no reply).
    SetServoDirect(f64),
    /// SET_YAW_OFFSET, degrees (no reply).
    SetYawOffset(f64),
    /// SET_YAW_OFFSET_ACK, degrees (acked).
    SetYawOffsetAck(f64),
    /// SET_MS_TODAY (no reply).
    SetMsToday(i32),
    /// ADD_UWB_ANCHOR.
    AddUwbAnchor(Anchor),
    /// CLEAR_UWB_ANCHORS.
    ClearUwbAnchors,
    /// SET_MAIN_CONFIG with the whole record.
    SetMainConfig(MainConfig),
    /// GET_MAIN_CONFIG.
    GetMainConfig,
    /// GET_MAIN_CONFIG_DEFAULT.
    GetMainConfigDefault,
    /// SEND_RTCM_USB: RTCM3 bytes for the GNSS receiver.
    SendRtcmUsb(Bytes),
    /// EMERGENCY_STOP: ignored by every firmware; use a brake instead.
    EmergencyStop,
    /// HEARTBEAT (12.1+): ignored by every firmware, does not feed the watchdog.
    Heartbeat,
    /// Any other command, data kept raw.
    Other {
        /// The wire id.
        code: u8,
        /// The data after `[id][cmd]`.
        data: Bytes,
    },
}

/// A car-to-host payload.
#[derive(Debug, Clone, PartialEq)]
pub enum Reply {
    /// The GET_STATE reply.
    State(CarState),
    /// PRINTF text (one line of terminal output, or an asynchronous debug print).
    Printf(String),
    /// The ack `[id][cmd]` of an acked command.
    Ack(CommandId),
    /// The GET_ENU_REF reply.
    EnuRef(EnuRef),
    /// The AP_GET_ROUTE_PART reply.
    RoutePart(RoutePart),
    /// The GET_MAIN_CONFIG (or `_DEFAULT`) reply.
    MainConfig {
        /// Whether this answers GET_MAIN_CONFIG_DEFAULT.
        default: bool,
        /// The record.
        config: MainConfig,
    },
    /// Any other packet, data kept raw.
    Other {
        /// The wire id.
        code: u8,
        /// The data after `[id][cmd]`.
        data: Bytes,
    },
}

/// Either direction, for code that handles both.
#[derive(Debug, Clone, PartialEq)]
pub enum Message {
    /// Host to car.
    Request(Request),
    /// Car to host.
    Reply(Reply),
}

/// Why a message cannot be encoded.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EncodeError {
    /// A number that cannot be put on the wire.
    #[error(transparent)]
    Number(#[from] NumberError),
    /// The command does not exist in this firmware version.
    #[error("{command:?} does not exist in firmware {version}")]
    NoSuchCommand {
        /// The command.
        command: CommandId,
        /// The version.
        version: FirmwareVersion,
    },
    /// A field this firmware version cannot carry (e.g. `attributes` before 12.0, `reset` before 12.3).
    #[error("{field} = {value} cannot be sent to firmware {version}")]
    Unsupported {
        /// The field.
        field: &'static str,
        /// Its value.
        value: String,
        /// The version.
        version: FirmwareVersion,
    },
    /// Text with a character outside Latin-1.
    #[error("{field}: character {character:?} at index {index} is not Latin-1")]
    NotLatin1 {
        /// The field.
        field: &'static str,
        /// The character.
        character: char,
        /// Its index (in characters).
        index: usize,
    },
    /// The payload would exceed what the receiver accepts.
    #[error("{what}: {len} exceeds the maximum of {max}")]
    TooLong {
        /// What is too long.
        what: &'static str,
        /// Its size.
        len: usize,
        /// The limit.
        max: usize,
    },
    /// Car id 211 makes the payload start with 0xD3, which the firmware takes for RTCM.
    #[error("car id 211 (0xD3) is reserved: the firmware parses such payloads as RTCM3")]
    ReservedCarId,
}

/// Why a payload cannot be decoded. Offsets are payload offsets (the id byte is offset 0).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum DecodeError {
    /// Fewer than the two header bytes.
    #[error("payload of {len} bytes has no [id][cmd] header")]
    NoHeader {
        /// The payload length.
        len: usize,
    },
    /// A payload starting with 0xD3, which the firmware treats as an RTCM3 stream.
    #[error("payload starts with 0xD3: an RTCM3 stream, not a command")]
    Rtcm,
    /// The data length does not match the layout.
    #[error("{command:?}: {found} data bytes, expected {expected}")]
    Length {
        /// The command.
        command: CommandId,
        /// The layout's length (or a description of the allowed lengths).
        expected: &'static str,
        /// The data length found.
        found: usize,
    },
    /// A point list that is not a multiple of the point size.
    #[error("{command:?}: {found} data bytes is not a multiple of the {point_size}-byte point")]
    PointsLength {
        /// The command.
        command: CommandId,
        /// The version's point size.
        point_size: usize,
        /// The data length found.
        found: usize,
    },
    /// A field with a value outside its domain.
    #[error("{command:?}: field {field} at payload offset {offset} has invalid value {value}")]
    InvalidValue {
        /// The command.
        command: CommandId,
        /// The field.
        field: &'static str,
        /// Payload offset of the field.
        offset: usize,
        /// The value found.
        value: i64,
    },
    /// A main-configuration record that does not fit the version's layout.
    #[error("{command:?}: {source}")]
    Config {
        /// The command.
        command: CommandId,
        /// What is wrong with the record.
        source: ConfigError,
    },
}

/// Writes data fields after the header.
struct Writer<'a> {
    out: &'a mut BytesMut,
    rounding: Rounding,
}

impl Writer<'_> {
    fn u8(&mut self, v: u8) {
        self.out.put_u8(v);
    }
    fn i16(&mut self, v: i16) {
        self.out.put_i16(v);
    }
    fn i32(&mut self, v: i32) {
        self.out.put_i32(v);
    }
    fn u32(&mut self, v: u32) {
        self.out.put_u32(v);
    }
    fn scaled(&mut self, field: &'static str, v: f64, scale: f64) -> Result<(), EncodeError> {
        self.out
            .put_i32(scaled_i32(field, v, scale, self.rounding)?);
        Ok(())
    }
    fn scaled64(&mut self, field: &'static str, v: f64, scale: f64) -> Result<(), EncodeError> {
        self.out
            .put_i64(scaled_i64(field, v, scale, self.rounding)?);
        Ok(())
    }
    fn auto(&mut self, field: &'static str, v: f32) -> Result<(), EncodeError> {
        self.out.put_u32(f32auto_encode(field, v)?);
        Ok(())
    }
    fn latin1(&mut self, field: &'static str, text: &str) -> Result<(), EncodeError> {
        for (index, character) in text.chars().enumerate() {
            let byte = u8::try_from(u32::from(character)).map_err(|_| EncodeError::NotLatin1 {
                field,
                character,
                index,
            })?;
            self.out.put_u8(byte);
        }
        Ok(())
    }
}

/// Reads data fields; every read is bounds-checked against a length verified beforehand.
struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        if let Some(bytes) = self.data.get(self.pos..self.pos + N) {
            out.copy_from_slice(bytes);
        }
        self.pos += N;
        out
    }
    fn u8(&mut self) -> u8 {
        self.take::<1>()[0]
    }
    fn i16(&mut self) -> i16 {
        i16::from_be_bytes(self.take())
    }
    fn i32(&mut self) -> i32 {
        i32::from_be_bytes(self.take())
    }
    fn u32(&mut self) -> u32 {
        u32::from_be_bytes(self.take())
    }
    fn i64(&mut self) -> i64 {
        i64::from_be_bytes(self.take())
    }
    fn scaled(&mut self, scale: f64) -> f64 {
        unscale_i32(self.i32(), scale)
    }
    fn auto(&mut self) -> f32 {
        f32auto_decode(self.u32())
    }
}

fn latin1(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| char::from(b)).collect()
}

fn expect_len(
    command: CommandId,
    data: &[u8],
    len: usize,
    expected: &'static str,
) -> Result<(), DecodeError> {
    if data.len() == len {
        Ok(())
    } else {
        Err(DecodeError::Length {
            command,
            expected,
            found: data.len(),
        })
    }
}

/// Splits a payload into `(id, cmd, data)`.
fn header(payload: &[u8]) -> Result<(u8, u8, &[u8]), DecodeError> {
    match payload {
        [RTCM_PREAMBLE, ..] => Err(DecodeError::Rtcm),
        [id, cmd, data @ ..] => Ok((*id, *cmd, data)),
        _ => Err(DecodeError::NoHeader { len: payload.len() }),
    }
}

fn start_payload(
    car: u8,
    command: CommandId,
    version: FirmwareVersion,
) -> Result<BytesMut, EncodeError> {
    if car == RTCM_PREAMBLE {
        return Err(EncodeError::ReservedCarId);
    }
    let code = command
        .code(version)
        .ok_or(EncodeError::NoSuchCommand { command, version })?;
    let mut out = BytesMut::with_capacity(32);
    out.put_u8(car);
    out.put_u8(code);
    Ok(out)
}

/// The room a reply's payload starts with: a GET_STATE reply, the one sent 20 times a second,
/// is 107 bytes from 12.3 (a 112-byte frame), so it is written without the buffer growing.
const REPLY_CAPACITY: usize = 128;

fn finish_payload(out: BytesMut) -> Result<Bytes, EncodeError> {
    if out.len() > FIRMWARE_MAX_PAYLOAD {
        return Err(EncodeError::TooLong {
            what: "payload",
            len: out.len(),
            max: FIRMWARE_MAX_PAYLOAD,
        });
    }
    Ok(out.freeze())
}

fn write_points(
    w: &mut Writer<'_>,
    points: &[RoutePoint],
    version: FirmwareVersion,
) -> Result<(), EncodeError> {
    let max = (FIRMWARE_MAX_PAYLOAD - 2) / version.route_point_size();
    if points.len() > max {
        return Err(EncodeError::TooLong {
            what: "route points in one packet",
            len: points.len(),
            max,
        });
    }
    let wide = version.route_point_size() == 24;
    for point in points {
        if !wide && point.attributes != 0 {
            let value = point.attributes.to_string();
            return Err(EncodeError::Unsupported {
                field: "attributes",
                value,
                version,
            });
        }
        w.scaled("px", point.px, SCALE_POSITION)?;
        w.scaled("py", point.py, SCALE_POSITION)?;
        if wide {
            w.scaled("pz", point.pz, SCALE_POSITION)?;
        }
        w.scaled("speed", point.speed, SCALE_FINE)?;
        w.i32(point.time_ms);
        if wide {
            w.u32(point.attributes);
        }
    }
    Ok(())
}

fn read_points(
    command: CommandId,
    data: &[u8],
    version: FirmwareVersion,
) -> Result<Vec<RoutePoint>, DecodeError> {
    let size = version.route_point_size();
    if !data.len().is_multiple_of(size) {
        return Err(DecodeError::PointsLength {
            command,
            point_size: size,
            found: data.len(),
        });
    }
    let mut r = Reader { data, pos: 0 };
    let points = (0..data.len() / size)
        .map(|_| {
            let px = r.scaled(SCALE_POSITION);
            let py = r.scaled(SCALE_POSITION);
            let pz = if size == 24 {
                r.scaled(SCALE_POSITION)
            } else {
                0.0
            };
            let speed = r.scaled(SCALE_FINE);
            let time_ms = r.i32();
            let attributes = if size == 24 { r.u32() } else { 0 };
            RoutePoint {
                px,
                py,
                pz,
                speed,
                time_ms,
                attributes,
            }
        })
        .collect();
    Ok(points)
}

fn write_pose(w: &mut Writer<'_>, pose: &Pose, yaw_field: &'static str) -> Result<(), EncodeError> {
    w.scaled("x", pose.x, SCALE_POSITION)?;
    w.scaled("y", pose.y, SCALE_POSITION)?;
    w.scaled(yaw_field, pose.yaw, SCALE_FINE)
}

fn write_enu_ref(w: &mut Writer<'_>, enu: &EnuRef) -> Result<(), EncodeError> {
    w.scaled64("lat", enu.lat, SCALE_LAT_LON)?;
    w.scaled64("lon", enu.lon, SCALE_LAT_LON)?;
    w.scaled("height", enu.height, SCALE_HEIGHT)
}

fn read_enu_ref(command: CommandId, data: &[u8]) -> Result<EnuRef, DecodeError> {
    expect_len(command, data, 20, "20")?;
    let mut r = Reader { data, pos: 0 };
    let lat = unscale_i64(r.i64(), SCALE_LAT_LON);
    let lon = unscale_i64(r.i64(), SCALE_LAT_LON);
    Ok(EnuRef {
        lat,
        lon,
        height: r.scaled(SCALE_HEIGHT),
    })
}

impl Request {
    /// The command this request carries.
    pub fn command(&self, version: FirmwareVersion) -> Option<CommandId> {
        match self {
            Request::Other { code, .. } => CommandId::from_code(*code, version),
            typed => typed.typed_command(),
        }
    }

    /// The command of a typed request; `None` for [`Request::Other`].
    fn typed_command(&self) -> Option<CommandId> {
        use CommandId as C;
        Some(match self {
            Request::GetState => C::GetState,
            Request::TerminalCmd(_) => C::TerminalCmd,
            Request::SetPos(_) => C::SetPos,
            Request::SetPosAck(_) => C::SetPosAck,
            Request::SetEnuRef(_) => C::SetEnuRef,
            Request::GetEnuRef => C::GetEnuRef,
            Request::AddPoints(_) => C::ApAddPoints,
            Request::ReplaceRoute(_) => C::ApReplaceRoute,
            Request::RemoveLastPoint => C::ApRemoveLastPoint,
            Request::ClearPoints => C::ApClearPoints,
            Request::GetRoutePart { .. } => C::ApGetRoutePart,
            Request::SetActive { .. } => C::ApSetActive,
            Request::SyncPoint(_) => C::ApSyncPoint,
            Request::RcControl(_) => C::RcControl,
            Request::SetServoDirect(_) => C::SetServoDirect,
            Request::SetYawOffset(_) => C::SetYawOffset,
            Request::SetYawOffsetAck(_) => C::SetYawOffsetAck,
            Request::SetMsToday(_) => C::SetMsToday,
            Request::AddUwbAnchor(_) => C::AddUwbAnchor,
            Request::ClearUwbAnchors => C::ClearUwbAnchors,
            Request::SetMainConfig(_) => C::SetMainConfig,
            Request::GetMainConfig => C::GetMainConfig,
            Request::GetMainConfigDefault => C::GetMainConfigDefault,
            Request::SendRtcmUsb(_) => C::SendRtcmUsb,
            Request::EmergencyStop => C::EmergencyStop,
            Request::Heartbeat => C::Heartbeat,
            Request::Other { .. } => return None,
        })
    }

    /// Encodes the payload `[car][cmd][data]` (not yet framed).
    pub fn encode(&self, car: u8, dialect: Dialect) -> Result<Bytes, EncodeError> {
        let version = dialect.version;
        let mut out = match self.typed_command() {
            Some(command) => start_payload(car, command, version)?,
            None if car == RTCM_PREAMBLE => return Err(EncodeError::ReservedCarId),
            None => {
                let code = if let Request::Other { code, .. } = self {
                    *code
                } else {
                    0
                };
                BytesMut::from(&[car, code][..])
            }
        };
        let mut w = Writer {
            out: &mut out,
            rounding: dialect.rounding,
        };
        match self {
            Request::GetState
            | Request::GetEnuRef
            | Request::RemoveLastPoint
            | Request::ClearPoints
            | Request::ClearUwbAnchors
            | Request::GetMainConfig
            | Request::GetMainConfigDefault
            | Request::EmergencyStop
            | Request::Heartbeat => {}
            Request::TerminalCmd(text) => w.latin1("terminal command", text)?,
            Request::SetPos(pose) | Request::SetPosAck(pose) => write_pose(&mut w, pose, "yaw")?,
            Request::SetEnuRef(enu) => write_enu_ref(&mut w, enu)?,
            Request::AddPoints(points) | Request::ReplaceRoute(points) => {
                write_points(&mut w, points, version)?
            }
            Request::GetRoutePart { first, num } => {
                w.i32(*first);
                w.u8(*num);
            }
            Request::SetActive { active, reset } => {
                w.u8(u8::from(*active));
                if version.set_active_has_reset() {
                    w.u8(u8::from(*reset));
                } else if *reset {
                    return Err(EncodeError::Unsupported {
                        field: "reset_state",
                        value: "1".into(),
                        version,
                    });
                }
            }
            Request::SyncPoint(sync) => {
                w.i32(sync.point);
                w.i32(sync.time_ms);
                w.i32(sync.min_diff_ms);
            }
            Request::RcControl(rc) => {
                w.u8(rc.mode as u8);
                w.scaled("throttle", rc.throttle, SCALE_POSITION)?;
                w.scaled("steering", rc.steering, SCALE_FINE)?;
            }
            Request::SetServoDirect(v) => w.scaled("servo", *v, SCALE_FINE)?,
            Request::SetYawOffset(v) | Request::SetYawOffsetAck(v) => {
                w.scaled("yaw offset", *v, SCALE_FINE)?
            }
            Request::SetMsToday(ms) => w.i32(*ms),
            Request::AddUwbAnchor(anchor) => {
                w.i16(anchor.id);
                w.auto("anchor px", anchor.px)?;
                w.auto("anchor py", anchor.py)?;
                w.auto("anchor height", anchor.height)?;
            }
            Request::SetMainConfig(config) => w.out.put_slice(config.record()),
            Request::SendRtcmUsb(bytes) | Request::Other { data: bytes, .. } => {
                w.out.put_slice(bytes)
            }
        }
        finish_payload(out)
    }

    /// Decodes a payload received by the car: `(car id, request)`.
    pub fn decode(payload: &[u8], version: FirmwareVersion) -> Result<(u8, Request), DecodeError> {
        let (car, code, data) = header(payload)?;
        let Some(command) = CommandId::from_code(code, version) else {
            return Ok((
                car,
                Request::Other {
                    code,
                    data: Bytes::copy_from_slice(data),
                },
            ));
        };
        let mut r = Reader { data, pos: 0 };
        let empty = |request: Request| expect_len(command, data, 0, "0").map(|_| request);
        let pose = |r: &mut Reader<'_>| -> Result<Pose, DecodeError> {
            expect_len(command, data, 12, "12")?;
            Ok(Pose {
                x: r.scaled(SCALE_POSITION),
                y: r.scaled(SCALE_POSITION),
                yaw: r.scaled(SCALE_FINE),
            })
        };
        let fine =
            |r: &mut Reader<'_>| expect_len(command, data, 4, "4").map(|_| r.scaled(SCALE_FINE));
        use CommandId as C;
        let request = match command {
            C::GetState => empty(Request::GetState)?,
            C::TerminalCmd => Request::TerminalCmd(latin1(data)),
            C::SetPos => Request::SetPos(pose(&mut r)?),
            C::SetPosAck => Request::SetPosAck(pose(&mut r)?),
            C::SetEnuRef => Request::SetEnuRef(read_enu_ref(command, data)?),
            C::GetEnuRef => empty(Request::GetEnuRef)?,
            C::ApAddPoints => Request::AddPoints(read_points(command, data, version)?),
            C::ApReplaceRoute => Request::ReplaceRoute(read_points(command, data, version)?),
            C::ApRemoveLastPoint => empty(Request::RemoveLastPoint)?,
            C::ApClearPoints => empty(Request::ClearPoints)?,
            C::ApGetRoutePart => {
                expect_len(command, data, 5, "5")?;
                Request::GetRoutePart {
                    first: r.i32(),
                    num: r.u8(),
                }
            }
            C::ApSetActive => {
                // 12.3 with a single byte: the firmware reads a stale byte; treat it
                // as 0 (`docs/protocol.md#clearing-and-activating`).
                if data.is_empty() || data.len() > 2 {
                    return Err(DecodeError::Length {
                        command,
                        expected: "1 or 2",
                        found: data.len(),
                    });
                }
                let active = r.u8() != 0;
                let reset = version.set_active_has_reset() && data.len() == 2 && r.u8() != 0;
                Request::SetActive { active, reset }
            }
            C::ApSyncPoint => {
                expect_len(command, data, 12, "12")?;
                Request::SyncPoint(SyncPoint {
                    point: r.i32(),
                    time_ms: r.i32(),
                    min_diff_ms: r.i32(),
                })
            }
            C::RcControl => {
                expect_len(command, data, 9, "9")?;
                let mode = match r.u8() {
                    0 => RcMode::Current,
                    1 => RcMode::Duty,
                    2 => RcMode::Pid,
                    3 => RcMode::CurrentBrake,
                    other => {
                        let value = i64::from(other);
                        return Err(DecodeError::InvalidValue {
                            command,
                            field: "mode",
                            offset: 2,
                            value,
                        });
                    }
                };
                let throttle = r.scaled(SCALE_POSITION);
                Request::RcControl(RcControl {
                    mode,
                    throttle,
                    steering: r.scaled(SCALE_FINE),
                })
            }
            C::SetServoDirect => Request::SetServoDirect(fine(&mut r)?),
            C::SetYawOffset => Request::SetYawOffset(fine(&mut r)?),
            C::SetYawOffsetAck => Request::SetYawOffsetAck(fine(&mut r)?),
            C::SetMsToday => {
                expect_len(command, data, 4, "4")?;
                Request::SetMsToday(r.i32())
            }
            C::AddUwbAnchor => {
                expect_len(command, data, 14, "14")?;
                Request::AddUwbAnchor(Anchor {
                    id: r.i16(),
                    px: r.auto(),
                    py: r.auto(),
                    height: r.auto(),
                })
            }
            C::ClearUwbAnchors => empty(Request::ClearUwbAnchors)?,
            C::SetMainConfig => {
                let config = MainConfig::from_record(version, data.to_vec())
                    .map_err(|source| DecodeError::Config { command, source })?;
                Request::SetMainConfig(config)
            }
            C::GetMainConfig => empty(Request::GetMainConfig)?,
            C::GetMainConfigDefault => empty(Request::GetMainConfigDefault)?,
            C::SendRtcmUsb => Request::SendRtcmUsb(Bytes::copy_from_slice(data)),
            C::EmergencyStop => Request::EmergencyStop,
            C::Heartbeat => Request::Heartbeat,
            _ => Request::Other {
                code,
                data: Bytes::copy_from_slice(data),
            },
        };
        Ok((car, request))
    }
}

/// Commands whose reply is the bare ack `[id][cmd]`.
pub fn is_acked(command: CommandId) -> bool {
    use CommandId as C;
    matches!(
        command,
        C::SetPosAck
            | C::SetEnuRef
            | C::ApAddPoints
            | C::ApRemoveLastPoint
            | C::ApClearPoints
            | C::ApSetActive
            | C::ApReplaceRoute
            | C::ApSyncPoint
            | C::SetYawOffsetAck
            | C::SetMainConfig
            | C::AddUwbAnchor
            | C::ClearUwbAnchors
            | C::SetSystemTimeAck
            | C::RebootSystemAck
            | C::IoBoardSetPwmDuty
            | C::IoBoardSetValve
    )
}

fn write_state(w: &mut Writer<'_>, s: &CarState) -> Result<(), EncodeError> {
    w.u8(s.version.major);
    w.u8(s.version.minor);
    w.scaled("roll", s.roll, SCALE_FINE)?;
    w.scaled("pitch", s.pitch, SCALE_FINE)?;
    w.scaled("yaw", s.yaw, SCALE_FINE)?;
    for (name, triple) in [("accel", &s.accel), ("gyro", &s.gyro), ("mag", &s.mag)] {
        for v in triple {
            w.scaled(name, *v, SCALE_FINE)?;
        }
    }
    w.scaled("px", s.px, SCALE_POSITION)?;
    w.scaled("py", s.py, SCALE_POSITION)?;
    w.scaled("speed", s.speed, SCALE_FINE)?;
    w.scaled("v_in", s.v_in, SCALE_FINE)?;
    w.scaled("temp_mos", s.temp_mos, SCALE_FINE)?;
    w.u8(s.mc_fault);
    w.scaled("px_gps", s.px_gps, SCALE_POSITION)?;
    w.scaled("py_gps", s.py_gps, SCALE_POSITION)?;
    w.scaled("ap_goal_px", s.ap_goal_px, SCALE_POSITION)?;
    w.scaled("ap_goal_py", s.ap_goal_py, SCALE_POSITION)?;
    w.scaled("ap_rad", s.ap_rad, SCALE_FINE)?;
    w.i32(s.ms_today);
    w.i16(s.ap_route_left);
    w.scaled("px_uwb", s.px_uwb, SCALE_POSITION)?;
    w.scaled("py_uwb", s.py_uwb, SCALE_POSITION)
}

fn read_state(data: &[u8]) -> Result<CarState, DecodeError> {
    expect_len(CommandId::GetState, data, STATE_PAYLOAD_LEN - 2, "105")?;
    let mut r = Reader { data, pos: 0 };
    let version = FirmwareVersion::new(r.u8(), r.u8());
    let triple = |r: &mut Reader<'_>| {
        [
            r.scaled(SCALE_FINE),
            r.scaled(SCALE_FINE),
            r.scaled(SCALE_FINE),
        ]
    };
    Ok(CarState {
        version,
        roll: r.scaled(SCALE_FINE),
        pitch: r.scaled(SCALE_FINE),
        yaw: r.scaled(SCALE_FINE),
        accel: triple(&mut r),
        gyro: triple(&mut r),
        mag: triple(&mut r),
        px: r.scaled(SCALE_POSITION),
        py: r.scaled(SCALE_POSITION),
        speed: r.scaled(SCALE_FINE),
        v_in: r.scaled(SCALE_FINE),
        temp_mos: r.scaled(SCALE_FINE),
        mc_fault: r.u8(),
        px_gps: r.scaled(SCALE_POSITION),
        py_gps: r.scaled(SCALE_POSITION),
        ap_goal_px: r.scaled(SCALE_POSITION),
        ap_goal_py: r.scaled(SCALE_POSITION),
        ap_rad: r.scaled(SCALE_FINE),
        ms_today: r.i32(),
        ap_route_left: r.i16(),
        px_uwb: r.scaled(SCALE_POSITION),
        py_uwb: r.scaled(SCALE_POSITION),
    })
}

impl Reply {
    /// The wire id this reply carries in `version` (`None` only for a command absent from that version).
    pub fn code(&self, version: FirmwareVersion) -> Option<u8> {
        match self {
            Reply::State(_) => CommandId::GetState.code(version),
            Reply::Printf(_) => CommandId::Printf.code(version),
            Reply::Ack(command) => command.code(version),
            Reply::EnuRef(_) => CommandId::GetEnuRef.code(version),
            Reply::RoutePart(_) => CommandId::ApGetRoutePart.code(version),
            Reply::MainConfig { default: false, .. } => CommandId::GetMainConfig.code(version),
            Reply::MainConfig { default: true, .. } => {
                CommandId::GetMainConfigDefault.code(version)
            }
            Reply::Other { code, .. } => Some(*code),
        }
    }

    /// Encodes the payload `[car][cmd][data]` (not yet framed). PRINTF text is limited to the version's maximum.
    pub fn encode(&self, car: u8, dialect: Dialect) -> Result<Bytes, EncodeError> {
        let version = dialect.version;
        if car == RTCM_PREAMBLE {
            return Err(EncodeError::ReservedCarId);
        }
        let code = match self.code(version) {
            Some(code) => code,
            None => {
                let command = match self {
                    Reply::Ack(command) => *command,
                    _ => CommandId::GetState,
                };
                return Err(EncodeError::NoSuchCommand { command, version });
            }
        };
        let mut out = BytesMut::with_capacity(REPLY_CAPACITY);
        out.put_u8(car);
        out.put_u8(code);
        let mut w = Writer {
            out: &mut out,
            rounding: dialect.rounding,
        };
        match self {
            Reply::State(state) => write_state(&mut w, state)?,
            Reply::Printf(text) => {
                let max = version.max_printf_len();
                let len = text.chars().count();
                if len > max {
                    return Err(EncodeError::TooLong {
                        what: "PRINTF text",
                        len,
                        max,
                    });
                }
                w.latin1("PRINTF text", text)?;
            }
            Reply::Ack(_) => {}
            Reply::EnuRef(enu) => write_enu_ref(&mut w, enu)?,
            Reply::RoutePart(part) => {
                w.i32(part.route_len);
                let wide = version.route_point_size() == 24;
                for p in &part.points {
                    w.auto("px", p.px as f32)?;
                    w.auto("py", p.py as f32)?;
                    if wide {
                        w.auto("pz", p.pz as f32)?;
                    }
                    w.auto("speed", p.speed as f32)?;
                    w.i32(p.time_ms);
                    if wide {
                        w.u32(p.attributes);
                    }
                }
            }
            Reply::MainConfig { config, .. } => w.out.put_slice(config.record()),
            Reply::Other { data, .. } => w.out.put_slice(data),
        }
        finish_payload(out)
    }

    /// Decodes a payload received by the host: `(car id, reply)`.
    ///
    /// An empty-data packet of an acked command is its [`Reply::Ack`]. A GET_STATE packet that is not 107 bytes
    /// (for example an echoed request) is an error, never a state.
    pub fn decode(payload: &[u8], version: FirmwareVersion) -> Result<(u8, Reply), DecodeError> {
        let (car, code, data) = header(payload)?;
        let Some(command) = CommandId::from_code(code, version) else {
            return Ok((
                car,
                Reply::Other {
                    code,
                    data: Bytes::copy_from_slice(data),
                },
            ));
        };
        use CommandId as C;
        let reply = match command {
            C::GetState => Reply::State(read_state(data)?),
            C::Printf => Reply::Printf(latin1(data)),
            C::GetEnuRef => Reply::EnuRef(read_enu_ref(command, data)?),
            C::ApGetRoutePart => Reply::RoutePart(read_route_part(data, version)?),
            C::GetMainConfig | C::GetMainConfigDefault => {
                let config = MainConfig::from_record(version, data.to_vec())
                    .map_err(|source| DecodeError::Config { command, source })?;
                Reply::MainConfig {
                    default: command == C::GetMainConfigDefault,
                    config,
                }
            }
            _ if is_acked(command) => {
                expect_len(command, data, 0, "0 (an ack)")?;
                Reply::Ack(command)
            }
            _ => Reply::Other {
                code,
                data: Bytes::copy_from_slice(data),
            },
        };
        Ok((car, reply))
    }
}

fn read_route_part(data: &[u8], version: FirmwareVersion) -> Result<RoutePart, DecodeError> {
    let command = CommandId::ApGetRoutePart;
    let size = version.route_point_size();
    if data.len() < 4 || !(data.len() - 4).is_multiple_of(size) {
        return Err(DecodeError::PointsLength {
            command,
            point_size: size,
            found: data.len().saturating_sub(4),
        });
    }
    let mut r = Reader { data, pos: 0 };
    let route_len = r.i32();
    let points = (0..(data.len() - 4) / size)
        .map(|_| {
            let px = f64::from(r.auto());
            let py = f64::from(r.auto());
            let pz = if size == 24 { f64::from(r.auto()) } else { 0.0 };
            let speed = f64::from(r.auto());
            let time_ms = r.i32();
            let attributes = if size == 24 { r.u32() } else { 0 };
            RoutePoint {
                px,
                py,
                pz,
                speed,
                time_ms,
                attributes,
            }
        })
        .collect();
    Ok(RoutePart { route_len, points })
}

impl Message {
    /// Decodes a payload travelling in `direction`: `(car id, message)`.
    pub fn decode(
        payload: &[u8],
        version: FirmwareVersion,
        direction: Direction,
    ) -> Result<(u8, Message), DecodeError> {
        match direction {
            Direction::ToCar => {
                Request::decode(payload, version).map(|(car, r)| (car, Message::Request(r)))
            }
            Direction::FromCar => {
                Reply::decode(payload, version).map(|(car, r)| (car, Message::Reply(r)))
            }
        }
    }

    /// Encodes the payload `[car][cmd][data]`.
    pub fn encode(&self, car: u8, dialect: Dialect) -> Result<Bytes, EncodeError> {
        match self {
            Message::Request(request) => request.encode(car, dialect),
            Message::Reply(reply) => reply.encode(car, dialect),
        }
    }

    /// Which way it travels.
    pub fn direction(&self) -> Direction {
        match self {
            Message::Request(_) => Direction::ToCar,
            Message::Reply(_) => Direction::FromCar,
        }
    }
}
