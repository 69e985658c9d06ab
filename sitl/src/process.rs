//! Running a built firmware executable and speaking its protocol (blocking, std::process).

use std::io::{BufReader, BufWriter, Read, Write};
use std::path::Path;
use std::process::{Child, ChildStdin, ChildStdout, Command, ExitStatus, Stdio};

use thiserror::Error;

use crate::protocol::{
    DecodeError, HostFrame, Imu, MAX_PAYLOAD, MotorValues, PROTOCOL_VERSION, SitlFrame,
};

/// Why talking to the executable failed.
#[derive(Debug, Error)]
pub enum SitlError {
    /// It could not be started.
    #[error("cannot start {path}: {source}")]
    Start {
        /// The executable.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// Its pipes failed, or it ended (`exit` says how, when known).
    #[error("the SITL executable's link failed: {source}{}", exit.map(|e| format!(" ({e})")).unwrap_or_default())]
    Link {
        /// Why.
        source: std::io::Error,
        /// Its exit status, when it has ended.
        exit: Option<ExitStatus>,
    },
    /// It sent something this protocol does not have.
    #[error("the SITL executable sent a bad frame: {0}")]
    Protocol(#[from] DecodeError),
    /// It speaks another protocol version, or did not start with HELLO.
    #[error("the SITL executable speaks protocol {found}, this crate {expected}")]
    Version {
        /// Ours.
        expected: u32,
        /// Its.
        found: u32,
    },
    /// It did not open with HELLO.
    #[error("the SITL executable did not open with HELLO but with {0:?}")]
    NoHello(Box<SitlFrame>),
    /// It stopped on an error of its own (a deadlock, a frame it refused).
    #[error("the firmware stopped: {0}")]
    Firmware(String),
}

/// A running firmware executable, in lockstep with its host.
///
/// Inputs ([`send_car_bytes`](Self::send_car_bytes), [`set_imu`](Self::set_imu), ...) take
/// effect at the current virtual time; [`advance_to`](Self::advance_to) then runs the firmware's
/// threads and timers up to a time and returns what it output on the way, in order.
#[derive(Debug)]
pub struct SitlProcess {
    child: Child,
    stdin: BufWriter<ChildStdin>,
    stdout: BufReader<ChildStdout>,
    firmware: (u8, u8),
    tick_hz: u32,
    now_us: u64,
}

impl SitlProcess {
    /// Starts the executable (stderr is inherited) and reads its HELLO.
    pub fn start(executable: &Path) -> Result<SitlProcess, SitlError> {
        let mut child = Command::new(executable)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|source| SitlError::Start {
                path: executable.display().to_string(),
                source,
            })?;
        let (Some(stdin), Some(stdout)) = (child.stdin.take(), child.stdout.take()) else {
            let _ = child.kill();
            return Err(SitlError::Start {
                path: executable.display().to_string(),
                source: std::io::Error::other("no pipes"),
            });
        };
        let mut p = SitlProcess {
            child,
            stdin: BufWriter::new(stdin),
            stdout: BufReader::new(stdout),
            firmware: (0, 0),
            tick_hz: 0,
            now_us: 0,
        };
        match p.read_frame()? {
            SitlFrame::Hello {
                protocol,
                firmware,
                tick_hz,
            } => {
                if protocol != PROTOCOL_VERSION {
                    let _ = p.child.kill();
                    return Err(SitlError::Version {
                        expected: PROTOCOL_VERSION,
                        found: protocol,
                    });
                }
                p.firmware = firmware;
                p.tick_hz = tick_hz;
            }
            other => {
                let _ = p.child.kill();
                return Err(SitlError::NoHello(Box::new(other)));
            }
        }
        Ok(p)
    }

    /// The executable's process id.
    pub fn id(&self) -> u32 {
        self.child.id()
    }

    /// The firmware version the executable was built from.
    pub fn firmware_version(&self) -> (u8, u8) {
        self.firmware
    }

    /// The firmware kernel's tick rate, Hz.
    pub fn tick_hz(&self) -> u32 {
        self.tick_hz
    }

    /// Virtual time reached, µs.
    pub fn now_us(&self) -> u64 {
        self.now_us
    }

    fn link_error(&mut self, source: std::io::Error) -> SitlError {
        let exit = self.child.try_wait().ok().flatten();
        SitlError::Link { source, exit }
    }

    fn send(&mut self, frame: &HostFrame) -> Result<(), SitlError> {
        let bytes = frame.encode();
        self.stdin.write_all(&bytes).map_err(|e| self.link_error(e))
    }

    fn read_frame(&mut self) -> Result<SitlFrame, SitlError> {
        let mut head = [0u8; 5];
        if let Err(e) = self.stdout.read_exact(&mut head) {
            return Err(self.link_error(e));
        }
        let len = u32::from_le_bytes([head[1], head[2], head[3], head[4]]) as usize;
        if len > MAX_PAYLOAD {
            return Err(SitlError::Protocol(DecodeError::TooLong(len)));
        }
        let mut payload = vec![0u8; len];
        if let Err(e) = self.stdout.read_exact(&mut payload) {
            return Err(self.link_error(e));
        }
        match SitlFrame::decode(head[0], &payload)? {
            SitlFrame::Error(text) => Err(SitlError::Firmware(text)),
            f => Ok(f),
        }
    }

    /// Bytes for the board's USB serial link (framed car protocol, as `car_link::frame` encodes).
    pub fn send_car_bytes(&mut self, bytes: &[u8]) -> Result<(), SitlError> {
        self.send(&HostFrame::CarBytes(bytes.to_vec()))
    }

    /// The IMU's values from now on.
    pub fn set_imu(&mut self, imu: Imu) -> Result<(), SitlError> {
        self.send(&HostFrame::Imu(imu))
    }

    /// White noise on every IMU sample from now on (g, °/s; deterministic from `seed`).
    pub fn set_imu_noise(
        &mut self,
        accel_sd: f32,
        gyro_sd: f32,
        seed: u64,
    ) -> Result<(), SitlError> {
        self.send(&HostFrame::ImuNoise {
            accel_sd,
            gyro_sd,
            seed,
        })
    }

    /// The motor controller's values from now on.
    pub fn set_motor_values(&mut self, values: MotorValues) -> Result<(), SitlError> {
        self.send(&HostFrame::MotorValues(values))
    }

    /// A GNSS NMEA sentence (`$GPGGA,...`).
    pub fn send_nmea(&mut self, sentence: &str) -> Result<(), SitlError> {
        self.send(&HostFrame::Nmea(sentence.to_string()))
    }

    /// The GNSS receiver's pulse per second, now ([`HostFrame::Pps`]).
    pub fn pps(&mut self) -> Result<(), SitlError> {
        self.send(&HostFrame::Pps)
    }

    /// A UWB range answer to a [`SitlFrame::UwbRequest`].
    pub fn send_uwb_range(&mut self, id: u8, dest: u8, range: f32) -> Result<(), SitlError> {
        self.send(&HostFrame::UwbRange { id, dest, range })
    }

    /// Runs the firmware to `t_us` of virtual time and returns its outputs on the way (not the
    /// final [`SitlFrame::Advanced`]). A time in the past runs nothing.
    pub fn advance_to(&mut self, t_us: u64) -> Result<Vec<SitlFrame>, SitlError> {
        self.send(&HostFrame::Advance(t_us))?;
        self.stdin.flush().map_err(|e| self.link_error(e))?;
        let mut out = Vec::new();
        loop {
            match self.read_frame()? {
                SitlFrame::Advanced(now) => {
                    self.now_us = now;
                    return Ok(out);
                }
                f => out.push(f),
            }
        }
    }

    /// Virtual time and the number of thread switches so far.
    pub fn stats(&mut self) -> Result<(u64, u64), SitlError> {
        self.send(&HostFrame::Stats)?;
        self.stdin.flush().map_err(|e| self.link_error(e))?;
        loop {
            if let SitlFrame::Stats { now_us, switches } = self.read_frame()? {
                return Ok((now_us, switches));
            }
        }
    }

    /// Ends the executable and waits for it.
    pub fn quit(mut self) -> Result<ExitStatus, SitlError> {
        let _ = self.send(&HostFrame::Quit);
        let _ = self.stdin.flush();
        self.child
            .wait()
            .map_err(|source| SitlError::Link { source, exit: None })
    }
}

impl Drop for SitlProcess {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    /// A stand-in executable: a shell script writing these bytes (octal escapes for printf), then
    /// reading its stdin until it ends.
    fn script(dir: &Path, name: &str, printf: &str) -> std::path::PathBuf {
        let p = dir.join(name);
        std::fs::write(
            &p,
            format!("#!/bin/sh\nprintf '{printf}'\ncat >/dev/null\n"),
        )
        .unwrap();
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755)).unwrap();
        p
    }

    // HELLO: type 0x80, length 10, protocol (u32 LE), 10, 1, tick 10000 (u32 LE)
    const HELLO_V1: &str =
        "\\200\\012\\000\\000\\000\\001\\000\\000\\000\\012\\001\\020\\047\\000\\000";

    #[test]
    fn refuses_another_protocol_version() {
        let t = tempfile::tempdir().unwrap();
        let exe = script(
            t.path(),
            "v2",
            "\\200\\012\\000\\000\\000\\002\\000\\000\\000\\012\\001\\020\\047\\000\\000",
        );
        match SitlProcess::start(&exe) {
            Err(SitlError::Version {
                expected: 1,
                found: 2,
            }) => {}
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn reads_hello_then_reports_the_firmware_error() {
        let t = tempfile::tempdir().unwrap();
        // HELLO, then ERROR "dead" (type 0x8F, length 4)
        let exe = script(
            t.path(),
            "err",
            &format!("{HELLO_V1}\\217\\004\\000\\000\\000dead"),
        );
        let mut p = SitlProcess::start(&exe).unwrap();
        assert_eq!((p.firmware_version(), p.tick_hz()), ((10, 1), 10_000));
        match p.advance_to(1000) {
            Err(SitlError::Firmware(text)) => assert_eq!(text, "dead"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn an_executable_that_ends_is_a_link_error() {
        let t = tempfile::tempdir().unwrap();
        let p = t.path().join("quits");
        std::fs::write(&p, format!("#!/bin/sh\nprintf '{HELLO_V1}'\nexit 5\n")).unwrap();
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755)).unwrap();
        let mut s = SitlProcess::start(&p).unwrap();
        match s.advance_to(1000) {
            Err(SitlError::Link { .. }) => {}
            other => panic!("{other:?}"),
        }
        let missing = t.path().join("missing");
        assert!(matches!(
            SitlProcess::start(&missing),
            Err(SitlError::Start { .. })
        ));
    }

    #[test]
    fn garbage_instead_of_hello() {
        let t = tempfile::tempdir().unwrap();
        let exe = script(t.path(), "garbage", "\\042\\000\\000\\000\\000");
        assert!(matches!(
            SitlProcess::start(&exe),
            Err(SitlError::Protocol(DecodeError::UnknownType(0x22)))
        ));
        let exe = script(
            t.path(),
            "advanced",
            "\\201\\010\\000\\000\\000\\000\\000\\000\\000\\000\\000\\000\\000",
        );
        assert!(matches!(
            SitlProcess::start(&exe),
            Err(SitlError::NoHello(_))
        ));
    }
}
