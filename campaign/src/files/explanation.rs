//! A failing segment's explanation as a case file records it (`explanation`): the record of
//! [`crate::explain::SegmentExplanation`], converted beside that type, so that the explanation's
//! own types can change without changing the case format.

use serde::{Deserialize, Serialize};

/// Where a cause comes from, as the case file writes it (`"source": "fault"`, …).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "source")]
pub enum SourceRecord {
    /// An injected fault.
    Fault {
        /// Its command's index in the case.
        command_index: usize,
    },
    /// An anchor's ranges.
    Anchor {
        /// Its id.
        anchor_id: u16,
    },
    /// The travelled distance fed to dead reckoning.
    Odometry,
    /// The yaw fed to dead reckoning.
    Heading,
    /// What no direction explains, and what stays below the threshold.
    Unexplained,
}

/// One cause of a segment's error growth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CauseRecord {
    /// Where it comes from.
    #[serde(flatten)]
    pub source: SourceRecord,
    /// Its share of the growth, 0–1.
    pub share: f64,
    /// The growth it explains, metres.
    pub growth_m: f64,
    /// Steps credited to it.
    pub steps: usize,
    /// `range`, `travel` or `yaw`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kind: Option<String>,
    /// Another cause that could not be told apart from this one in a step credited to it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ambiguous_with: Option<SourceRecord>,
}

/// A segment's explanation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SegmentExplanationRecord {
    /// The segment's index.
    pub segment_index: usize,
    /// `failed` or `passed`.
    pub verdict: String,
    /// The growth interval, seconds since the test began.
    pub from_s: f64,
    /// Its end.
    pub to_s: f64,
    /// |e| at the start of the interval, metres.
    pub error_from_m: f64,
    /// |e| at its end.
    pub error_to_m: f64,
    /// The error carried over from before the segment.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub carried_over: bool,
    /// The causes, most growth first; `unexplained` last.
    pub causes: Vec<CauseRecord>,
}
