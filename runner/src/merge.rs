//! The shards' recordings joined into the whole campaign's (`drivecheck runs merge`): every
//! shard's tests' messages in test order, each test's log time shifted to follow the one before
//! it as in an unsharded run; messages of a recording made without test spans (one car for the
//! whole shard) follow, a shard at a time.
//!
//! The shards' recordings are read from their files a span at a time, one test per shard in
//! memory (a recording without test spans is one span), and checked as they are read: of the
//! shard's campaign (its seed), a span for every test of the shard that did not pass and none
//! for another's, no damage. A shard refused half way stops the merge.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use recording::{
    LoadedProfile, LoadedProfileError, Recorder, RecordingError, RecordingStart,
    SIM_PROFILE_METADATA, Span, Spans,
};
use thiserror::Error;

use crate::fresh::SPAN_GAP_NS;
use crate::store::RECORDING_FILE;
use campaign::files::CampaignRecord;
use campaign::oracle::Verdict;
use campaign::shard::Shard;

/// One shard as the merge of recordings reads it.
#[derive(Debug, Clone, Copy)]
pub struct ShardRun<'a> {
    /// Its run directory.
    pub dir: &'a Path,
    /// Its `campaign.json`.
    pub record: &'a CampaignRecord,
    /// Which shard it is.
    pub shard: Shard,
}

/// A shard's recording that cannot be merged.
#[derive(Debug, Error)]
pub enum MergeError {
    /// A shard's recording cannot be opened.
    #[error("{}", dir.display())]
    Recording {
        /// The shard's directory.
        dir: PathBuf,
        /// Why.
        #[source]
        source: Box<RecordingError>,
    },
    /// A shard's recording is damaged.
    #[error("{}: {RECORDING_FILE}", dir.display())]
    Damaged {
        /// The shard's directory.
        dir: PathBuf,
        /// Why.
        #[source]
        source: Box<RecordingError>,
    },
    /// The merged recording cannot be written.
    #[error(transparent)]
    Write(Box<RecordingError>),
    /// A span of a test the shard does not run.
    #[error("{}: {RECORDING_FILE} holds test {test}, which is not in shard {shard}", dir.display())]
    NotInShard {
        /// The shard's directory.
        dir: PathBuf,
        /// The test.
        test: usize,
        /// The shard.
        shard: Shard,
    },
    /// Two spans of one test.
    #[error("{}: {RECORDING_FILE} holds test {test} twice", dir.display())]
    Twice {
        /// The shard's directory.
        dir: PathBuf,
        /// The test.
        test: usize,
    },
    /// The recording of another campaign.
    #[error(
        "{}: {RECORDING_FILE} is the recording of campaign seed {recorded}, campaign.json's is {seed}",
        dir.display()
    )]
    OtherCampaign {
        /// The shard's directory.
        dir: PathBuf,
        /// The seed the recording names.
        recorded: String,
        /// The seed of its `campaign.json`.
        seed: u64,
    },
    /// A test that did not pass has no span.
    #[error(
        "{}: {RECORDING_FILE} has no span of test {test}, which did not pass: it is not this \
         shard's recording, or it was cut",
        dir.display()
    )]
    Missing {
        /// The shard's directory.
        dir: PathBuf,
        /// The test.
        test: usize,
    },
    /// The car profile the first shard recorded does not load.
    #[error(transparent)]
    Profile(#[from] LoadedProfileError),
}

impl From<RecordingError> for MergeError {
    fn from(error: RecordingError) -> Self {
        MergeError::Write(Box::new(error))
    }
}

/// A shard's recording as the merge reads it: a span at a time from the file, each checked
/// against the shard's campaign as it is read (see [`ShardSpans::peek`]).
struct ShardSpans<'a> {
    shard: ShardRun<'a>,
    spans: Spans<std::io::BufReader<std::fs::File>>,
    /// The span read ahead, checked.
    next: Option<Span>,
    /// The tests whose spans were read.
    seen: BTreeSet<usize>,
}

impl<'a> ShardSpans<'a> {
    fn open(shard: ShardRun<'a>) -> Result<Self, MergeError> {
        let spans = Spans::open(&shard.dir.join(RECORDING_FILE)).map_err(|source| {
            MergeError::Recording {
                dir: shard.dir.to_owned(),
                source: Box::new(source),
            }
        })?;
        Ok(Self {
            shard,
            spans,
            next: None,
            seen: BTreeSet::new(),
        })
    }

    /// The next span's test (`Some(None)`: a span without a test; `None`: the end), the span
    /// read ahead and checked: damage is refused, and so is a span of a test that is not in the
    /// shard, or of a test read before.
    fn peek(&mut self, verdicts: &[Option<Verdict>]) -> Result<Option<Option<usize>>, MergeError> {
        if self.next.is_none() {
            let dir = self.shard.dir;
            let span = match self.spans.next() {
                None => return Ok(None),
                Some(span) => span.map_err(|source| MergeError::Damaged {
                    dir: dir.to_owned(),
                    source: Box::new(source),
                })?,
            };
            if let Some(test) = span.test_index {
                if test >= verdicts.len() || !self.shard.shard.contains(test) {
                    return Err(MergeError::NotInShard {
                        dir: dir.to_owned(),
                        test,
                        shard: self.shard.shard,
                    });
                }
                if !self.seen.insert(test) {
                    return Err(MergeError::Twice {
                        dir: dir.to_owned(),
                        test,
                    });
                }
            }
            self.next = Some(span);
        }
        Ok(self.next.as_ref().map(|span| span.test_index))
    }

    /// The span read ahead.
    fn take(&mut self) -> Option<Span> {
        self.next.take()
    }

    /// Checks that the recording is of the shard's campaign (its seed): the campaign's metadata
    /// record comes before any message, so it is read once a span is.
    fn check_campaign(&self) -> Result<(), MergeError> {
        let seed = self
            .spans
            .metadata("drivecheck.campaign")
            .and_then(|m| m.get("seed"))
            .map(String::as_str);
        if seed != Some(self.shard.record.seed.to_string().as_str()) {
            return Err(MergeError::OtherCampaign {
                dir: self.shard.dir.to_owned(),
                recorded: seed.unwrap_or("(none recorded)").to_owned(),
                seed: self.shard.record.seed,
            });
        }
        Ok(())
    }

    /// Once the recording is read to its end: it has a span of every test of the shard that did
    /// not pass (a recording of the embedded simulator has one per test it keeps; `--record
    /// failing` drops the others).
    fn check_every_test(&self, verdicts: &[Option<Verdict>]) -> Result<(), MergeError> {
        if self.shard.record.car == "sim"
            && let Some(missing) = (0..verdicts.len())
                .filter(|&t| self.shard.shard.contains(t))
                .find(|&t| verdicts[t] != Some(Verdict::Passed) && !self.seen.contains(&t))
        {
            return Err(MergeError::Missing {
                dir: self.shard.dir.to_owned(),
                test: missing,
            });
        }
        Ok(())
    }
}

/// Writes `out`, the recording of the campaign `record` whose tests ended with `verdicts`, from
/// the recordings of its `shards` (see the module doc).
pub fn merge_recordings(
    shards: &[ShardRun<'_>],
    verdicts: &[Option<Verdict>],
    record: &CampaignRecord,
    scenario: &scenarios::Scenario,
    out: &Path,
) -> Result<(), MergeError> {
    let mut readers: Vec<ShardSpans<'_>> = shards
        .iter()
        .map(|shard| ShardSpans::open(*shard))
        .collect::<Result<_, _>>()?;
    // Every shard read up to its first span, where its campaign's metadata has been read.
    for reader in &mut readers {
        reader.peek(verdicts)?;
        reader.check_campaign()?;
    }
    let simulated = shards.iter().all(|s| s.record.car == "sim");
    let at_start = CampaignRecord {
        ended_at: None,
        summary: None,
        ..record.clone()
    };
    // The simulated car's profile, as the first shard recorded it (the shards agree on its
    // hash: it is in their campaign records).
    let profile = match readers.first() {
        Some(reader) => reader
            .spans
            .metadata(SIM_PROFILE_METADATA)
            .map(LoadedProfile::from_metadata)
            .transpose()?,
        None => None,
    };
    let start = RecordingStart {
        campaign: &at_start,
        scenario,
        origin: tokio::time::Instant::now(),
        simulated,
        chunk_interval: recording::DEFAULT_CHUNK_INTERVAL,
        live: None,
        // Shards on the embedded simulator ran a fresh car per test: every test has a span.
        test_spans: simulated,
        sim_profile: profile.as_ref(),
    };
    let mut recorder = Recorder::create(out, &start)?;
    let mut offset_ns = SPAN_GAP_NS;
    loop {
        // The shard whose next span is the lowest test.
        let mut best: Option<(usize, usize)> = None;
        for (position, reader) in readers.iter_mut().enumerate() {
            if let Some(Some(test)) = reader.peek(verdicts)?
                && best.is_none_or(|(_, b)| test < b)
            {
                best = Some((position, test));
            }
        }
        let Some((position, _)) = best else {
            break;
        };
        if let Some(span) = readers[position].take() {
            write_span(&mut recorder, span, &mut offset_ns)?;
        }
    }
    // Only spans without a test are left: each shard's in turn, each shard read to its end.
    for reader in &mut readers {
        while reader.peek(verdicts)?.is_some() {
            if let Some(span) = reader.take() {
                write_span(&mut recorder, span, &mut offset_ns)?;
            }
        }
        reader.check_every_test(verdicts)?;
    }
    recorder.campaign_ended(record)?;
    recorder.finish()?;
    Ok(())
}

/// Writes `span`'s messages starting at `offset_ns`, with its test's span record, and moves the
/// offset past it.
fn write_span(
    recorder: &mut Recorder,
    span: Span,
    offset_ns: &mut u64,
) -> Result<(), RecordingError> {
    let length = span.end_ns.saturating_sub(span.start_ns);
    let shift = offset_ns.wrapping_sub(span.start_ns);
    recorder.copy_span(span, shift)?;
    *offset_ns += length + SPAN_GAP_NS;
    Ok(())
}
