//! The SITL executable's host protocol (`docs/sitl.md`): frames on its stdin and stdout.
//!
//! Every frame is `[type: u8][length: u32 LE][payload]`; numbers in payloads are little-endian,
//! floats IEEE-754 binary32, times `u64` microseconds of virtual time since the executable
//! started. The host's frames are [`HostFrame`]s; the executable's are [`SitlFrame`]s.

use thiserror::Error;

/// The protocol version this crate speaks (the HELLO frame's first field).
pub const PROTOCOL_VERSION: u32 = 1;
/// The longest payload either side accepts.
pub const MAX_PAYLOAD: usize = 1 << 20;

/// An IMU sample as the firmware's IMU driver delivers it: accelerations in g, rates in
/// degrees per second, the magnetometer raw, in the board's axes.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Imu {
    /// Acceleration x, y, z, g.
    pub accel: [f32; 3],
    /// Angular rate x, y, z, °/s.
    pub gyro: [f32; 3],
    /// Magnetic field x, y, z.
    pub mag: [f32; 3],
}

/// What the motor controller (VESC) answers to the firmware's value requests.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MotorValues {
    /// Electrical RPM.
    pub rpm: f32,
    /// Tachometer, electrical steps (six a revolution of the electrical field), signed.
    pub tachometer: i32,
    /// Tachometer, absolute.
    pub tachometer_abs: i32,
    /// Input voltage, V (also what the board's own ADC reads).
    pub v_in: f32,
    /// Motor current, A.
    pub current_motor: f32,
    /// Duty cycle, −1 to 1.
    pub duty_now: f32,
}

/// A frame from the host.
#[derive(Debug, Clone, PartialEq)]
pub enum HostFrame {
    /// Run the firmware to this virtual time (µs); answered by [`SitlFrame::Advanced`] after all
    /// the outputs produced on the way.
    Advance(u64),
    /// Bytes on the board's USB serial link, for the firmware's `packet.c` (framed car protocol).
    CarBytes(Vec<u8>),
    /// The IMU's values from now on (sample and hold; the IMU samples at its own rate).
    Imu(Imu),
    /// The motor controller's values from now on.
    MotorValues(MotorValues),
    /// A GNSS NMEA sentence, for the firmware's `pos_input_nmea()`.
    Nmea(String),
    /// A UWB range answer: the requesting module's id, the anchor (`dest`) and the range in m.
    UwbRange {
        /// The id in the request.
        id: u8,
        /// The anchor.
        dest: u8,
        /// Metres.
        range: f32,
    },
    /// White noise added to every IMU sample from now on (standard deviations in g and °/s),
    /// from a deterministic generator with this seed. Zero turns it off (the default).
    ImuNoise {
        /// Accelerometer noise, g.
        accel_sd: f32,
        /// Gyro noise, °/s.
        gyro_sd: f32,
        /// The generator's seed.
        seed: u64,
    },
    /// Ask for [`SitlFrame::Stats`].
    Stats,
    /// The GNSS receiver's pulse per second, now (the firmware's `pos_pps_cb`, which sets its
    /// time of day to the whole second after the last NMEA time stamp: a board with
    /// `UBLOX_USE_PPS` keeps its clock by it, not by the NMEA time).
    Pps,
    /// End the executable.
    Quit,
}

/// What the firmware commands the motor controller to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MotorCommand {
    /// Duty cycle, −1 to 1.
    Duty(f32),
    /// Motor current, A.
    Current(f32),
    /// Braking current, A.
    CurrentBrake(f32),
    /// Electrical RPM.
    Rpm(f32),
    /// Position, degrees.
    Pos(f32),
    /// Handbrake current, A.
    Handbrake(f32),
}

/// A frame from the executable.
#[derive(Debug, Clone, PartialEq)]
pub enum SitlFrame {
    /// First frame: protocol version, firmware version, kernel tick rate (Hz).
    Hello {
        /// [`PROTOCOL_VERSION`] of the shim.
        protocol: u32,
        /// `FW_VERSION_MAJOR`, `FW_VERSION_MINOR`.
        firmware: (u8, u8),
        /// `CH_CFG_ST_FREQUENCY`.
        tick_hz: u32,
    },
    /// Virtual time reached (µs).
    Advanced(u64),
    /// Bytes the firmware sent on its USB serial link (framed car protocol), at a time.
    CarBytes {
        /// Virtual µs.
        t_us: u64,
        /// The bytes.
        bytes: Vec<u8>,
    },
    /// A motor command, at a time.
    Motor {
        /// Virtual µs.
        t_us: u64,
        /// The command.
        command: MotorCommand,
    },
    /// The steering servo's new position (0 to 1), at a time.
    Servo {
        /// Virtual µs.
        t_us: u64,
        /// Position.
        pos: f32,
    },
    /// The firmware asks a UWB module (`id`) for the range to anchor `dest`.
    UwbRequest {
        /// Virtual µs.
        t_us: u64,
        /// The module asked (255: any).
        id: u8,
        /// The anchor.
        dest: u8,
        /// Samples to average.
        samples: i32,
    },
    /// A note from the shim (`init done` when the firmware's start-up finished).
    Note {
        /// Virtual µs.
        t_us: u64,
        /// Text.
        text: String,
    },
    /// Statistics: virtual time and context switches so far.
    Stats {
        /// Virtual µs.
        now_us: u64,
        /// Thread switches.
        switches: u64,
    },
    /// The executable stopped on an error (a deadlock, a bad frame); it exits after this.
    Error(String),
}

/// A frame that does not decode.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum DecodeError {
    /// Fewer bytes than the header or the payload needs.
    #[error("incomplete frame")]
    Incomplete,
    /// A type byte this protocol does not have.
    #[error("unknown frame type 0x{0:02x}")]
    UnknownType(u8),
    /// A payload of the wrong length for its type.
    #[error("frame type 0x{kind:02x}: payload of {len} bytes")]
    BadLength {
        /// The type.
        kind: u8,
        /// The length.
        len: usize,
    },
    /// A length beyond [`MAX_PAYLOAD`].
    #[error("frame of {0} bytes is too long")]
    TooLong(usize),
}

fn frame(kind: u8, payload: &[u8]) -> Vec<u8> {
    let mut v = Vec::with_capacity(5 + payload.len());
    v.push(kind);
    v.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    v.extend_from_slice(payload);
    v
}

impl HostFrame {
    /// The frame's bytes.
    pub fn encode(&self) -> Vec<u8> {
        match self {
            HostFrame::Advance(t) => frame(0x01, &t.to_le_bytes()),
            HostFrame::CarBytes(b) => frame(0x02, b),
            HostFrame::Imu(imu) => {
                let mut p = Vec::with_capacity(36);
                for v in imu.accel.iter().chain(&imu.gyro).chain(&imu.mag) {
                    p.extend_from_slice(&v.to_le_bytes());
                }
                frame(0x03, &p)
            }
            HostFrame::MotorValues(m) => {
                let mut p = Vec::with_capacity(24);
                // on the wire all six are f32, as the shim stores them
                for v in [
                    m.rpm,
                    m.tachometer as f32,
                    m.tachometer_abs as f32,
                    m.v_in,
                    m.current_motor,
                    m.duty_now,
                ] {
                    p.extend_from_slice(&v.to_le_bytes());
                }
                frame(0x04, &p)
            }
            HostFrame::Nmea(s) => frame(0x05, s.as_bytes()),
            HostFrame::UwbRange { id, dest, range } => {
                let mut p = vec![*id, *dest];
                p.extend_from_slice(&range.to_le_bytes());
                frame(0x06, &p)
            }
            HostFrame::Stats => frame(0x07, &[]),
            HostFrame::Pps => frame(0x09, &[]),
            HostFrame::ImuNoise {
                accel_sd,
                gyro_sd,
                seed,
            } => {
                let mut p = Vec::with_capacity(16);
                p.extend_from_slice(&accel_sd.to_le_bytes());
                p.extend_from_slice(&gyro_sd.to_le_bytes());
                p.extend_from_slice(&seed.to_le_bytes());
                frame(0x08, &p)
            }
            HostFrame::Quit => frame(0x0F, &[]),
        }
    }
}

/// Splits one frame off the front of `buf`: `(type, payload, bytes used)`.
pub fn split_frame(buf: &[u8]) -> Result<(u8, &[u8], usize), DecodeError> {
    let head = buf.get(..5).ok_or(DecodeError::Incomplete)?;
    let len = u32::from_le_bytes([head[1], head[2], head[3], head[4]]) as usize;
    if len > MAX_PAYLOAD {
        return Err(DecodeError::TooLong(len));
    }
    let payload = buf.get(5..5 + len).ok_or(DecodeError::Incomplete)?;
    Ok((head[0], payload, 5 + len))
}

fn u64_at(p: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(p.get(at..at + 8)?.try_into().ok()?))
}
fn u32_at(p: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(p.get(at..at + 4)?.try_into().ok()?))
}
fn f32_at(p: &[u8], at: usize) -> Option<f32> {
    u32_at(p, at).map(f32::from_bits)
}

impl SitlFrame {
    /// Decodes a frame's type and payload (from [`split_frame`]).
    pub fn decode(kind: u8, p: &[u8]) -> Result<SitlFrame, DecodeError> {
        let bad = || DecodeError::BadLength { kind, len: p.len() };
        let exact = |n: usize| if p.len() == n { Ok(()) } else { Err(bad()) };
        Ok(match kind {
            0x80 => {
                exact(10)?;
                SitlFrame::Hello {
                    protocol: u32_at(p, 0).ok_or_else(bad)?,
                    firmware: (p[4], p[5]),
                    tick_hz: u32_at(p, 6).ok_or_else(bad)?,
                }
            }
            0x81 => {
                exact(8)?;
                SitlFrame::Advanced(u64_at(p, 0).ok_or_else(bad)?)
            }
            0x82 => SitlFrame::CarBytes {
                t_us: u64_at(p, 0).ok_or_else(bad)?,
                bytes: p[8..].to_vec(),
            },
            0x83 => {
                exact(13)?;
                let v = f32_at(p, 9).ok_or_else(bad)?;
                let command = match p[8] {
                    1 => MotorCommand::Duty(v),
                    2 => MotorCommand::Current(v),
                    3 => MotorCommand::CurrentBrake(v),
                    4 => MotorCommand::Rpm(v),
                    5 => MotorCommand::Pos(v),
                    6 => MotorCommand::Handbrake(v),
                    _ => return Err(bad()),
                };
                SitlFrame::Motor {
                    t_us: u64_at(p, 0).ok_or_else(bad)?,
                    command,
                }
            }
            0x84 => {
                exact(12)?;
                SitlFrame::Servo {
                    t_us: u64_at(p, 0).ok_or_else(bad)?,
                    pos: f32_at(p, 8).ok_or_else(bad)?,
                }
            }
            0x85 => {
                exact(14)?;
                SitlFrame::UwbRequest {
                    t_us: u64_at(p, 0).ok_or_else(bad)?,
                    id: p[8],
                    dest: p[9],
                    samples: u32_at(p, 10).ok_or_else(bad)? as i32,
                }
            }
            0x86 => SitlFrame::Note {
                t_us: u64_at(p, 0).ok_or_else(bad)?,
                text: String::from_utf8_lossy(&p[8..]).into_owned(),
            },
            0x87 => {
                exact(16)?;
                SitlFrame::Stats {
                    now_us: u64_at(p, 0).ok_or_else(bad)?,
                    switches: u64_at(p, 8).ok_or_else(bad)?,
                }
            }
            0x8F => SitlFrame::Error(String::from_utf8_lossy(p).into_owned()),
            other => return Err(DecodeError::UnknownType(other)),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn advance_is_type_length_then_time() {
        assert_eq!(
            HostFrame::Advance(0x0102).encode(),
            vec![1, 8, 0, 0, 0, 2, 1, 0, 0, 0, 0, 0, 0]
        );
    }

    #[test]
    fn imu_and_motor_payloads_have_the_lengths_the_shim_checks() {
        assert_eq!(HostFrame::Imu(Imu::default()).encode().len(), 5 + 36);
        assert_eq!(
            HostFrame::MotorValues(MotorValues::default())
                .encode()
                .len(),
            5 + 24
        );
        assert_eq!(
            HostFrame::ImuNoise {
                accel_sd: 0.0,
                gyro_sd: 0.0,
                seed: 1
            }
            .encode()
            .len(),
            5 + 16
        );
        let r = HostFrame::UwbRange {
            id: 255,
            dest: 3,
            range: 2.5,
        }
        .encode();
        assert_eq!(r[..7], [6, 6, 0, 0, 0, 255, 3]);
        assert_eq!(f32::from_le_bytes(r[7..11].try_into().unwrap()), 2.5);
    }

    #[test]
    fn split_frame_needs_the_whole_payload() {
        let f = frame(0x81, &7u64.to_le_bytes());
        assert_eq!(split_frame(&f[..4]), Err(DecodeError::Incomplete));
        assert_eq!(split_frame(&f[..12]), Err(DecodeError::Incomplete));
        let (k, p, used) = split_frame(&f).unwrap();
        assert_eq!((k, used), (0x81, 13));
        assert_eq!(SitlFrame::decode(k, p), Ok(SitlFrame::Advanced(7)));
        let huge = [0x82, 0xff, 0xff, 0xff, 0xff];
        assert_eq!(split_frame(&huge), Err(DecodeError::TooLong(0xffff_ffff)));
    }

    #[test]
    fn decodes_every_output_and_refuses_bad_lengths() {
        let mut hello = 1u32.to_le_bytes().to_vec();
        hello.extend([12, 3]);
        hello.extend(10000u32.to_le_bytes());
        assert_eq!(
            SitlFrame::decode(0x80, &hello),
            Ok(SitlFrame::Hello {
                protocol: 1,
                firmware: (12, 3),
                tick_hz: 10000
            })
        );
        assert_eq!(
            SitlFrame::decode(0x80, &hello[..9]),
            Err(DecodeError::BadLength { kind: 0x80, len: 9 })
        );

        let mut motor = 5u64.to_le_bytes().to_vec();
        motor.push(3);
        motor.extend(10.0f32.to_le_bytes());
        assert_eq!(
            SitlFrame::decode(0x83, &motor),
            Ok(SitlFrame::Motor {
                t_us: 5,
                command: MotorCommand::CurrentBrake(10.0)
            })
        );
        motor[8] = 9;
        assert!(SitlFrame::decode(0x83, &motor).is_err());

        let mut uwb = 9u64.to_le_bytes().to_vec();
        uwb.extend([255, 4]);
        uwb.extend(5i32.to_le_bytes());
        assert_eq!(
            SitlFrame::decode(0x85, &uwb),
            Ok(SitlFrame::UwbRequest {
                t_us: 9,
                id: 255,
                dest: 4,
                samples: 5
            })
        );

        let mut car = 1u64.to_le_bytes().to_vec();
        car.extend([2, 2, 0, 120]);
        assert_eq!(
            SitlFrame::decode(0x82, &car),
            Ok(SitlFrame::CarBytes {
                t_us: 1,
                bytes: vec![2, 2, 0, 120]
            })
        );
        assert_eq!(
            SitlFrame::decode(0x82, &car[..7]),
            Err(DecodeError::BadLength { kind: 0x82, len: 7 })
        );
        assert_eq!(
            SitlFrame::decode(0x8F, b"deadlock"),
            Ok(SitlFrame::Error("deadlock".into()))
        );
        assert_eq!(
            SitlFrame::decode(0x42, &[]),
            Err(DecodeError::UnknownType(0x42))
        );
    }
}
