//! Fault injection through terminal commands (`docs/protocol.md#terminal-commands`,
//! `docs/firmware.md#fault-injection`): probes, fault kinds, the command texts and the parsing of the firmware's PRINTF
//! replies into typed outcomes.

use std::fmt;
use std::str::FromStr;

use thiserror::Error;

/// The longest probe id the firmware stores.
pub const MAX_PROBE_ID: usize = 20;

/// A fault-injection probe: a place in the firmware where a value can be disturbed, named by its
/// probe id (`uwb_range_50`). With the `serde` feature it is written as that id.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(try_from = "String", into = "String")
)]
pub enum Probe {
    /// The fused `px` packed into the GET_STATE reply (once per GET_STATE).
    Px,
    /// The odometry distance step fed to UWB dead reckoning (every odometry tick).
    UwbTravelDist,
    /// The yaw fed to UWB dead reckoning (every odometry tick).
    UwbYaw,
    /// The measured range to one anchor (every range reply from it).
    UwbRange(u16),
}

impl fmt::Display for Probe {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Probe::Px => f.write_str("px"),
            Probe::UwbTravelDist => f.write_str("uwb_travel_dist"),
            Probe::UwbYaw => f.write_str("uwb_yaw"),
            Probe::UwbRange(anchor) => write!(f, "uwb_range_{anchor}"),
        }
    }
}

/// A probe id the firmware does not know.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("unknown probe {0:?}: expected px, uwb_travel_dist, uwb_yaw or uwb_range_<anchor id>")]
pub struct UnknownProbe(pub String);

impl FromStr for Probe {
    type Err = UnknownProbe;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "px" => Ok(Probe::Px),
            "uwb_travel_dist" => Ok(Probe::UwbTravelDist),
            "uwb_yaw" => Ok(Probe::UwbYaw),
            // The firmware compares probe ids as text: only the id's canonical decimal
            // (`uwb_range_7`, not `uwb_range_07` or `uwb_range_+7`) names the probe it calls.
            _ => s
                .strip_prefix("uwb_range_")
                .and_then(|id| id.parse::<u16>().ok().filter(|n| n.to_string() == id))
                .map(Probe::UwbRange)
                .ok_or_else(|| UnknownProbe(s.into())),
        }
    }
}

/// A probe is written as its id: a string of the ids the firmware knows.
#[cfg(feature = "serde")]
impl schemars::JsonSchema for Probe {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "Probe".into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "description": "A fault-injection probe id: px, uwb_travel_dist, uwb_yaw or uwb_range_<anchor id>.",
            "type": "string",
            "pattern": "^(px|uwb_travel_dist|uwb_yaw|uwb_range_(0|[1-9][0-9]{0,4}))$",
        })
    }
}

impl From<Probe> for String {
    fn from(probe: Probe) -> Self {
        probe.to_string()
    }
}

impl TryFrom<String> for Probe {
    type Error = UnknownProbe;

    fn try_from(s: String) -> Result<Self, Self::Error> {
        s.parse()
    }
}

/// What a fault does to the probed value: the kinds and their table live in the firmware model.
pub use crate::firmware::fault_kinds::FaultKind;

/// One reason the firmware gave for refusing a fault-injection command.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FaultRejection {
    /// `Too long ID. Maximum length is 20`.
    TooLongId,
    /// `Invalid fault type <type>`.
    InvalidType(String),
    /// `Too many faults on this probe, fault not added.` (5 slots, never freed until `fi_clear_faults`).
    TooManyFaults,
    /// `Too many probes in use, fault not added.` (5 probes).
    TooManyProbes,
    /// `Wrong number of arguments`.
    WrongArgumentCount,
    /// `Invalid argument <arg>`.
    InvalidArgument(String),
}

impl fmt::Display for FaultRejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FaultRejection::TooLongId => f.write_str("probe id too long (maximum 20)"),
            FaultRejection::InvalidType(kind) => write!(f, "invalid fault type {kind}"),
            FaultRejection::TooManyFaults => f.write_str("too many faults on this probe"),
            FaultRejection::TooManyProbes => f.write_str("too many probes in use"),
            FaultRejection::WrongArgumentCount => f.write_str("wrong number of arguments"),
            FaultRejection::InvalidArgument(arg) => write!(f, "invalid argument {arg}"),
        }
    }
}

/// A fault-injection command that did not do what was asked.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum FaultError {
    /// The firmware refused it, for these reasons (it can print several).
    #[error("fault injection refused: {}", .0.iter().map(ToString::to_string).collect::<Vec<_>>().join("; "))]
    Rejected(Vec<FaultRejection>),
    /// The reply matched neither success nor a known refusal.
    #[error("unexpected fault-injection reply {0:?}")]
    Unexpected(String),
    /// The probe id is longer than the firmware accepts (checked before sending).
    #[error("probe id {0:?} is longer than 20 characters")]
    ProbeIdTooLong(String),
    /// No reply text arrived.
    #[error("no reply to the fault-injection command")]
    NoReply,
    /// The reply to `fi_add_fault` was lost and the car's fault list, which would tell whether it
    /// took effect, could not be read either (why, in words).
    #[error(
        "the reply to the fault command was lost, and whether it took effect cannot be told: the \
         car's fault list could not be read ({0})"
    )]
    Unconfirmed(String),
    /// No reply named the probe of a `fi_add_fault` sent while no other was in flight, but the
    /// car printed a success line naming another probe: a reply drivecheck does not recognise.
    #[error("the car answered {reply:?} to a fault for probe {asked}, which names another probe")]
    OtherProbe {
        /// The probe id the command named.
        asked: String,
        /// The success lines the car printed meanwhile.
        reply: String,
    },
    /// Part of the reply arrived, not all of it (a lossy link lost some of its lines).
    #[error("the reply to {0} arrived incomplete (some of its lines were lost on the link)")]
    Incomplete(&'static str),
}

/// The terminal command adding a fault. `param` is written with a decimal point, as in the protocol's vector.
pub fn add_fault_command(
    probe: &Probe,
    kind: FaultKind,
    param: f32,
    start: i32,
    duration: i32,
) -> String {
    format!("fi_add_fault {probe} {kind} {param:?} {start} {duration}")
}

/// The terminal command switching fault injection on or off.
pub fn set_enabled_command(enabled: bool) -> String {
    format!("fi_set_enabled {}", u8::from(enabled))
}

/// The terminal command freeing every probe and slot.
pub const CLEAR_FAULTS_COMMAND: &str = "fi_clear_faults";
/// The terminal command resetting the UWB position to the fused one.
pub const RESET_UWB_POS_COMMAND: &str = "pos_uwb_reset_pos";

fn rejection(line: &str) -> Option<FaultRejection> {
    let line = line.trim_end_matches('\n');
    if line.starts_with("Too long ID") {
        Some(FaultRejection::TooLongId)
    } else if let Some(kind) = line.strip_prefix("Invalid fault type ") {
        Some(FaultRejection::InvalidType(kind.to_string()))
    } else if line.starts_with("Too many faults on this probe") {
        Some(FaultRejection::TooManyFaults)
    } else if line.starts_with("Too many probes in use") {
        Some(FaultRejection::TooManyProbes)
    } else if line.starts_with("Wrong number of arguments") {
        Some(FaultRejection::WrongArgumentCount)
    } else {
        line.strip_prefix("Invalid argument")
            .map(|arg| FaultRejection::InvalidArgument(arg.trim().to_string()))
    }
}

/// Whether a PRINTF line answers a fault-injection command (as opposed to an unrelated debug print).
pub fn is_fault_reply(line: &str) -> bool {
    rejection(line).is_some()
        || line.contains("successfully added to probe")
        || line.starts_with("Fault Injection ")
        || line.starts_with("Faults cleared")
        || line.starts_with("UWB Pos")
}

fn outcome(lines: &[String], success: impl Fn(&str) -> bool) -> Result<(), FaultError> {
    if lines.is_empty() {
        return Err(FaultError::NoReply);
    }
    let rejections: Vec<FaultRejection> = lines.iter().filter_map(|l| rejection(l)).collect();
    if !rejections.is_empty() {
        return Err(FaultError::Rejected(rejections));
    }
    if lines.iter().any(|l| success(l)) {
        return Ok(());
    }
    Err(FaultError::Unexpected(lines.concat()))
}

/// Parses the reply lines of `fi_add_fault` for `probe`: success only on `successfully added to probe <probe>`.
/// The car prints either that line or refusals, never both: with fault commands for other probes in flight
/// at the same time, a refusal next to this probe's success line is another command's.
pub fn parse_add_fault_reply(lines: &[String], probe: &Probe) -> Result<(), FaultError> {
    let expected = add_fault_success(probe);
    if lines.iter().any(|l| l.contains(&expected)) {
        return Ok(());
    }
    outcome(lines, |l| l.contains(&expected))
}

/// Whether a PRINTF line may answer `fi_add_fault` for `probe`: its success line, or a refusal (which names no
/// probe).
pub fn is_add_fault_reply(line: &str, probe: &Probe) -> bool {
    line.contains(&add_fault_success(probe)) || rejection(line).is_some()
}

/// Whether a PRINTF line is a success line of `fi_add_fault`, for whatever probe.
pub fn is_add_fault_success(line: &str) -> bool {
    line.contains("successfully added to probe ")
}

fn add_fault_success(probe: &Probe) -> String {
    format!("successfully added to probe {probe}.")
}

/// The terminal command listing the faults added since the last clear.
pub const PRINT_FAULTS_COMMAND: &str = "fi_print_faults";

/// A fault as `fi_print_faults` lists it (expired faults included: they keep their slot).
#[derive(Debug, Clone, PartialEq)]
pub struct ListedFault {
    /// The probe id (`uwb_range_50`, `uwb_yaw`, …).
    pub probe: String,
    /// The probe's iteration counter now.
    pub iteration: i64,
    /// The fault type as printed (`OFFSET`, …).
    pub kind: String,
    /// The parameter, as printed with two decimals.
    pub param: f32,
    /// The absolute iteration it starts at.
    pub start: i64,
    /// Iterations it applies for.
    pub duration: i64,
}

/// Whether a PRINTF line belongs to the reply of `fi_print_faults`.
pub fn is_print_faults_reply(line: &str) -> bool {
    line.starts_with("Currently active faults:") || line.starts_with("\nProbe") || line == " "
}

/// Whether the reply lines of `fi_print_faults` are complete (the header, then the final space).
pub fn print_faults_complete(lines: &[String]) -> bool {
    lines
        .first()
        .is_some_and(|l| l.starts_with("Currently active faults:"))
        && lines.last().is_some_and(|l| l == " ")
}

/// Parses the reply lines of `fi_print_faults`: one block per fault
/// (`\nProbe   : <id>\nIT now  : <n>\nType    : <TYPE>\nParam   : <p>\nStart   : <it>\nDuration: <n>`).
pub fn parse_print_faults_reply(lines: &[String]) -> Result<Vec<ListedFault>, FaultError> {
    if lines.is_empty() {
        return Err(FaultError::NoReply);
    }
    if !print_faults_complete(lines) {
        return Err(FaultError::Incomplete(PRINT_FAULTS_COMMAND));
    }
    lines[1..lines.len() - 1]
        .iter()
        .map(|block| parse_listed_fault(block).ok_or_else(|| FaultError::Unexpected(block.clone())))
        .collect()
}

/// The fault blocks of whatever part of a `fi_print_faults` reply arrived: on a lossy link a
/// reply may lack its header, its last line or some blocks, but a block that arrived whole is
/// a fault the car holds (lines are lost, never made up). Complete or not, what it shows.
/// [`FaultError::NoReply`] when nothing arrived.
pub fn parse_print_faults_part(lines: &[String]) -> Result<Vec<ListedFault>, FaultError> {
    if lines.is_empty() {
        return Err(FaultError::NoReply);
    }
    Ok(lines
        .iter()
        .filter(|l| l.starts_with("\nProbe"))
        .filter_map(|block| parse_listed_fault(block))
        .collect())
}

fn parse_listed_fault(block: &str) -> Option<ListedFault> {
    let mut fields = block
        .split('\n')
        .filter(|l| !l.is_empty())
        .map(|l| l.split_once(':').map(|(k, v)| (k.trim(), v.trim())));
    let mut next = |key: &str| match fields.next() {
        Some(Some((k, v))) if k == key => Some(v.to_string()),
        _ => None,
    };
    Some(ListedFault {
        probe: next("Probe")?,
        iteration: next("IT now")?.parse().ok()?,
        kind: next("Type")?,
        param: next("Param")?.parse().ok()?,
        start: next("Start")?.parse().ok()?,
        duration: next("Duration")?.parse().ok()?,
    })
}

/// Parses the reply lines of `fi_set_enabled`.
pub fn parse_set_enabled_reply(lines: &[String], enabled: bool) -> Result<(), FaultError> {
    let expected = if enabled {
        "Fault Injection enabled"
    } else {
        "Fault Injection disabled"
    };
    outcome(lines, |l| l.starts_with(expected))
}

/// Parses the reply lines of `fi_clear_faults`.
pub fn parse_clear_faults_reply(lines: &[String]) -> Result<(), FaultError> {
    outcome(lines, |l| l.starts_with("Faults cleared"))
}

/// Parses the reply lines of `pos_uwb_reset_pos` (`UWB Position Reset`; the bridge simulator says `UWB Pos reset`).
pub fn parse_reset_uwb_reply(lines: &[String]) -> Result<(), FaultError> {
    outcome(lines, |l| l.starts_with("UWB Pos"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lines(texts: &[&str]) -> Vec<String> {
        texts.iter().map(|t| t.to_string()).collect()
    }

    #[test]
    fn probes_print_and_parse_as_the_firmware_names_them() {
        for probe in [
            Probe::Px,
            Probe::UwbRange(0),
            Probe::UwbRange(255),
            Probe::UwbRange(u16::MAX),
            Probe::UwbTravelDist,
            Probe::UwbYaw,
        ] {
            assert_eq!(probe.to_string().parse::<Probe>(), Ok(probe));
        }
        assert_eq!(Probe::UwbRange(7).to_string(), "uwb_range_7");
    }

    #[test]
    fn only_the_canonical_probe_id_parses() {
        // The firmware compares ids as text: `uwb_range_07` is not the probe of anchor 7.
        for name in [
            "uwb_range_",
            "uwb_range_65536",
            "uwb_range_+1",
            "uwb_range_07",
            "UWB_YAW",
            "uwb_yaw ",
        ] {
            assert!(name.parse::<Probe>().is_err(), "{name}");
        }
    }

    #[test]
    fn command_text_matches_the_protocol_vector() {
        let command = add_fault_command(&Probe::UwbRange(50), FaultKind::Offset, 2.0, 15, 8);
        assert_eq!(command, "fi_add_fault uwb_range_50 OFFSET 2.0 15 8");
    }

    #[test]
    fn success_is_recognised() {
        let reply = lines(&[
            "Fault OFFSET with parameter 2.00 successfully added to probe uwb_range_50.\n",
        ]);
        assert_eq!(parse_add_fault_reply(&reply, &Probe::UwbRange(50)), Ok(()));
        assert!(matches!(
            parse_add_fault_reply(&reply, &Probe::Px),
            Err(FaultError::Unexpected(_))
        ));
    }

    #[test]
    fn refusals_are_typed() {
        let reply = lines(&[
            "Too long ID. Maximum length is 20\n",
            "Invalid fault type offset\n",
        ]);
        assert_eq!(
            parse_add_fault_reply(&reply, &Probe::Px),
            Err(FaultError::Rejected(vec![
                FaultRejection::TooLongId,
                FaultRejection::InvalidType("offset".into())
            ]))
        );
        let full = lines(&["Too many faults on this probe, fault not added.\n"]);
        assert_eq!(
            parse_add_fault_reply(&full, &Probe::Px),
            Err(FaultError::Rejected(vec![FaultRejection::TooManyFaults]))
        );
        // Another probe's command in flight was refused; this one's succeeded.
        let mixed = lines(&[
            "Too many faults on this probe, fault not added.\n",
            "Fault OFFSET with parameter 2.00 successfully added to probe uwb_yaw.\n",
        ]);
        assert_eq!(parse_add_fault_reply(&mixed, &Probe::UwbYaw), Ok(()));
        assert!(is_add_fault_reply(&mixed[1], &Probe::UwbYaw));
        assert!(!is_add_fault_reply(&mixed[1], &Probe::UwbRange(50)));
        assert!(is_add_fault_reply(&mixed[0], &Probe::UwbRange(50)));
        let probes = lines(&["Too many probes in use, fault not added.\n"]);
        assert_eq!(
            parse_add_fault_reply(&probes, &Probe::UwbYaw),
            Err(FaultError::Rejected(vec![FaultRejection::TooManyProbes]))
        );
        assert_eq!(
            parse_set_enabled_reply(&lines(&["Invalid argument 2\n"]), true),
            Err(FaultError::Rejected(vec![FaultRejection::InvalidArgument(
                "2".into()
            )]))
        );
        assert_eq!(parse_clear_faults_reply(&[]), Err(FaultError::NoReply));
    }

    #[test]
    fn the_fault_list_parses_block_by_block() {
        let lines: Vec<String> = [
            "Currently active faults:",
            "\nProbe   : uwb_range_50\nIT now  : 12\nType    : OFFSET\nParam   : 4.00\nStart   : 20\nDuration: 8",
            "\nProbe   : uwb_yaw\nIT now  : 400\nType    : AMPLIFICATION\nParam   : -1.50\nStart   : 405\nDuration: 3",
            " ",
        ]
        .map(String::from)
        .to_vec();
        assert!(lines.iter().all(|l| is_print_faults_reply(l)));
        let faults = parse_print_faults_reply(&lines).unwrap();
        assert_eq!(faults.len(), 2);
        assert_eq!(faults[0].probe, "uwb_range_50");
        assert_eq!(faults[1].kind, "AMPLIFICATION");
        assert_eq!(faults[1].param, -1.5);
        assert_eq!(
            (faults[1].iteration, faults[1].start, faults[1].duration),
            (400, 405, 3)
        );
        let empty: Vec<String> = ["Currently active faults:", " "].map(String::from).to_vec();
        assert_eq!(parse_print_faults_reply(&empty), Ok(vec![]));
        assert_eq!(parse_print_faults_reply(&[]), Err(FaultError::NoReply));
        assert!(parse_print_faults_reply(&lines[..2]).is_err());
        let mut garbled = lines.clone();
        garbled[1] = "\nProbe   : uwb_yaw\nIT now  : x".to_string();
        assert!(matches!(
            parse_print_faults_reply(&garbled),
            Err(FaultError::Unexpected(_))
        ));
        // A part of the list: the header and the first block lost, the others as they came.
        assert_eq!(
            parse_print_faults_reply(&lines[2..]),
            Err(FaultError::Incomplete(PRINT_FAULTS_COMMAND))
        );
        let part = parse_print_faults_part(&lines[2..]).unwrap();
        assert_eq!(part.len(), 1);
        assert_eq!(part[0].probe, "uwb_yaw");
        assert_eq!(parse_print_faults_part(&garbled).unwrap().len(), 1);
        assert_eq!(parse_print_faults_part(&[]), Err(FaultError::NoReply));
    }

    #[test]
    fn other_replies_are_recognised() {
        assert_eq!(
            parse_set_enabled_reply(&lines(&["Fault Injection enabled\n"]), true),
            Ok(())
        );
        assert!(parse_set_enabled_reply(&lines(&["Fault Injection disabled\n"]), true).is_err());
        assert_eq!(
            parse_clear_faults_reply(&lines(&["Faults cleared\n"])),
            Ok(())
        );
        assert_eq!(
            parse_reset_uwb_reply(&lines(&["UWB Position Reset\n"])),
            Ok(())
        );
        assert_eq!(parse_reset_uwb_reply(&lines(&["UWB Pos reset\n"])), Ok(()));
    }

    #[test]
    fn probes_round_trip() {
        for probe in [
            Probe::Px,
            Probe::UwbTravelDist,
            Probe::UwbYaw,
            Probe::UwbRange(7),
        ] {
            assert_eq!(probe.to_string().parse(), Ok(probe));
        }
        assert!("uwb_range_x".parse::<Probe>().is_err());
    }
}
