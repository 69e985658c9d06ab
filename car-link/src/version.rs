//! The command-id table (`docs/protocol.md#command-ids`): each command's wire id in each firmware
//! version ([`FirmwareVersion::new_command_ids`] says which numbering a version uses; every
//! version-dependent fact is in `crate::firmware`).

use crate::firmware::FirmwareVersion;

macro_rules! commands {
    ($( $(#[$doc:meta])* $name:ident = $new:expr, $old:expr, $resets:expr; )*) => {
        /// Every command of the protocol's id table (`docs/protocol.md#command-ids`). Its wire id depends on the
        /// firmware version.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum CommandId {
            $( $(#[$doc])* $name, )*
        }

        impl CommandId {
            /// Every command, in table order.
            pub const ALL: &'static [CommandId] = &[$(CommandId::$name,)*];

            /// The wire id in `version`; `None` if the command does not exist there.
            pub fn code(self, version: FirmwareVersion) -> Option<u8> {
                self.code_in(version.new_command_ids())
            }

            /// The wire id in the new numbering (`new_ids`) or the old one.
            const fn code_in(self, new_ids: bool) -> Option<u8> {
                match self {
                    $( CommandId::$name => if new_ids { $new } else { $old }, )*
                }
            }

            /// Whether the firmware's communication watchdog is reset by this command (`docs/protocol.md#watchdog`).
            pub fn resets_watchdog(self) -> bool {
                match self {
                    $( CommandId::$name => $resets, )*
                }
            }
        }
    };
}

commands! {
    /// Text output of the car (always stamped with the car's own id).
    Printf = Some(0), Some(0), false;
    /// A terminal command; replies with zero or more PRINTF.
    TerminalCmd = Some(1), Some(1), true;
    /// Forwarded to the motor controller.
    VescFwd = Some(50), Some(50), true;
    /// Sets the pose; no reply.
    SetPos = Some(51), Some(51), true;
    /// Sets the pose; acked.
    SetPosAck = Some(52), Some(52), true;
    /// Sets the ENU reference; acked.
    SetEnuRef = Some(53), Some(53), true;
    /// Reads the ENU reference.
    GetEnuRef = Some(54), Some(54), true;
    /// Appends route points; acked.
    ApAddPoints = Some(55), Some(55), true;
    /// Removes the last route point; acked.
    ApRemoveLastPoint = Some(56), Some(56), true;
    /// Empties the route and deactivates the autopilot; acked.
    ApClearPoints = Some(57), Some(57), true;
    /// Reads part of the route (no reply if more than 20 points are asked for).
    ApGetRoutePart = Some(58), Some(58), false;
    /// Activates or deactivates the autopilot; acked.
    ApSetActive = Some(59), Some(59), true;
    /// Replaces the route from the current segment on; acked.
    ApReplaceRoute = Some(60), Some(60), true;
    /// Re-times the route up to a point; acked.
    ApSyncPoint = Some(61), Some(61), true;
    /// RTCM3 correction bytes for the GNSS receiver.
    SendRtcmUsb = Some(62), Some(62), false;
    /// NMEA text over the radio.
    SendNmeaRadio = Some(63), Some(63), false;
    /// Sets the IMU yaw offset; no reply.
    SetYawOffset = Some(64), Some(64), true;
    /// Sets the IMU yaw offset; acked.
    SetYawOffsetAck = Some(65), Some(65), true;
    /// A log line for the bridge.
    LogLineUsb = Some(66), Some(66), false;
    /// Plot set-up.
    PlotInit = Some(67), Some(67), false;
    /// Plot data.
    PlotData = Some(68), Some(68), false;
    /// Plot graph added.
    PlotAddGraph = Some(69), Some(69), false;
    /// Plot graph selected.
    PlotSetGraph = Some(70), Some(70), false;
    /// Sets `ms_today`; no reply.
    SetMsToday = Some(71), Some(71), true;
    /// Sets the bridge's system time.
    SetSystemTime = Some(72), Some(72), false;
    /// Sets the bridge's system time; acked.
    SetSystemTimeAck = Some(73), Some(73), false;
    /// Reboots the bridge.
    RebootSystem = Some(74), Some(74), false;
    /// Reboots the bridge; acked.
    RebootSystemAck = Some(75), Some(75), false;
    /// Obsolete radar set-up (old numbering only).
    RadarSetupSet = None, Some(76), false;
    /// Obsolete radar read-back (old numbering only).
    RadarSetupGet = None, Some(77), false;
    /// Obsolete radar samples (old numbering only).
    RadarSamples = None, Some(78), false;
    /// Obsolete DW sample (old numbering only).
    DwSample = None, Some(79), false;
    /// Declared but handled nowhere: ignored by every firmware.
    EmergencyStop = Some(76), Some(80), false;
    /// Writes the main configuration to flash; acked after the write.
    SetMainConfig = Some(77), Some(81), true;
    /// Reads the main configuration.
    GetMainConfig = Some(78), Some(82), true;
    /// Reads the default main configuration.
    GetMainConfigDefault = Some(79), Some(83), true;
    /// Adds a UWB anchor; acked.
    AddUwbAnchor = Some(80), Some(84), false;
    /// Removes all UWB anchors; acked.
    ClearUwbAnchors = Some(81), Some(85), false;
    /// Ethernet log for the bridge.
    LogEthernet = Some(82), Some(86), false;
    /// A camera image (bridge).
    CameraImage = Some(83), Some(87), false;
    /// Starts the camera stream (bridge).
    CameraStreamStart = Some(84), Some(88), false;
    /// Acknowledges a camera frame (bridge).
    CameraFrameAck = Some(85), Some(89), false;
    /// IO board PWM duty (new numbering only).
    IoBoardSetPwmDuty = Some(86), None, false;
    /// IO board valve (new numbering only).
    IoBoardSetValve = Some(87), None, false;
    /// Hydraulic move (new numbering only).
    HydraulicMove = Some(88), None, false;
    /// Sent by the control station, ignored by every firmware (new numbering only).
    Heartbeat = Some(89), None, false;
    /// Reads the car state (`docs/protocol.md#state-reply`).
    GetState = Some(120), Some(120), true;
    /// Manual throttle and steering; no reply.
    RcControl = Some(121), Some(121), true;
    /// Sets the steering servo directly; no reply.
    SetServoDirect = Some(122), Some(122), true;
    /// Multirotor state.
    MrGetState = Some(160), Some(160), false;
    /// Multirotor manual control.
    MrRcControl = Some(161), Some(161), false;
    /// Multirotor power override.
    MrOverridePower = Some(162), Some(162), false;
    /// Radio mote: start the UBX base.
    MoteUbxStartBase = Some(200), Some(200), false;
    /// Radio mote: UBX base started.
    MoteUbxStartBaseAck = Some(201), Some(201), false;
    /// Radio mote: UBX base status.
    MoteUbxBaseStatus = Some(202), Some(202), false;
}

impl CommandId {
    /// The command with wire id `code` in `version`, if any.
    pub fn from_code(code: u8, version: FirmwareVersion) -> Option<CommandId> {
        BY_CODE[usize::from(version.new_command_ids())][usize::from(code)]
    }
}

/// [`CommandId::from_code`]'s tables, old numbering then new: the first command in table order
/// with each id (a search of the table for every message decoded was a percent of a simulated
/// test).
static BY_CODE: [[Option<CommandId>; 256]; 2] = [by_code(false), by_code(true)];

const fn by_code(new_ids: bool) -> [Option<CommandId>; 256] {
    let mut table = [None; 256];
    let mut i = CommandId::ALL.len();
    // Backwards, so that the first command with an id is the one left.
    while i > 0 {
        i -= 1;
        if let Some(code) = CommandId::ALL[i].code_in(new_ids) {
            table[code as usize] = Some(CommandId::ALL[i]);
        }
    }
    table
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tables give what a search of the command table gives, for every id and version.
    #[test]
    fn the_id_tables_are_the_command_table_searched() {
        for version in [
            FirmwareVersion::V10_1,
            FirmwareVersion::V10_2,
            FirmwareVersion::V11_0,
            FirmwareVersion::V12_0,
            FirmwareVersion::V12_1,
            FirmwareVersion::V12_3,
            FirmwareVersion::new(13, 0),
        ] {
            for code in 0..=255u8 {
                let searched = CommandId::ALL
                    .iter()
                    .copied()
                    .find(|c| c.code(version) == Some(code));
                assert_eq!(
                    CommandId::from_code(code, version),
                    searched,
                    "{code} in {version}"
                );
            }
        }
    }

    #[test]
    fn ids_76_to_89_change_at_12_1() {
        assert_eq!(
            CommandId::AddUwbAnchor.code(FirmwareVersion::V12_1),
            Some(80)
        );
        assert_eq!(
            CommandId::AddUwbAnchor.code(FirmwareVersion::V12_0),
            Some(84)
        );
        assert_eq!(
            CommandId::from_code(80, FirmwareVersion::V12_0),
            Some(CommandId::EmergencyStop)
        );
        assert_eq!(
            CommandId::from_code(89, FirmwareVersion::V10_1),
            Some(CommandId::CameraFrameAck)
        );
        assert_eq!(
            CommandId::from_code(89, FirmwareVersion::V12_3),
            Some(CommandId::Heartbeat)
        );
        assert_eq!(CommandId::Heartbeat.code(FirmwareVersion::V11_0), None);
        assert_eq!(CommandId::RadarSetupSet.code(FirmwareVersion::V12_3), None);
    }

    #[test]
    fn ids_are_unique_in_every_generation() {
        for version in [
            FirmwareVersion::V10_1,
            FirmwareVersion::V12_0,
            FirmwareVersion::V12_3,
        ] {
            for code in 0..=255u8 {
                let n = CommandId::ALL
                    .iter()
                    .filter(|c| c.code(version) == Some(code))
                    .count();
                assert!(n <= 1, "id {code} is used {n} times in {version}");
            }
        }
    }
}
