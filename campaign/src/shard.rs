//! Shards: a deterministic partition of a campaign's tests, so that one campaign runs as N jobs
//! of a batch engine (a Kubernetes Indexed Job, a Slurm job array, a CI matrix) and the jobs'
//! run directories merge into the run directory of the whole campaign (`drivecheck runs merge`).
//!
//! Shard `K/N` (K from 1 to N) holds the tests whose index `i` has `i mod N = K − 1`: round robin,
//! so that every shard gets tests from the whole campaign and the shards' sizes differ by at most
//! one (the convention of `cargo nextest --partition count:K/N`).

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// One shard of a campaign: `index` of `count` (from 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Shard {
    /// Which shard, from 1 to `count`.
    pub index: usize,
    /// How many shards the campaign is split into.
    pub count: usize,
}

/// Why a shard is not `K/N` with 1 ≤ K ≤ N.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ShardError {
    /// Not two whole numbers around a `/`.
    #[error("`{0}`: a shard is K/N, two whole numbers (for example 2/8)")]
    Syntax(String),
    /// K or N out of range.
    #[error("`{0}`: a shard K/N needs 1 ≤ K ≤ N (shards count from 1)")]
    Range(String),
}

impl Shard {
    /// Shard `index` of `count`, checked.
    pub fn new(index: usize, count: usize) -> Result<Self, ShardError> {
        if index == 0 || count == 0 || index > count {
            return Err(ShardError::Range(format!("{index}/{count}")));
        }
        Ok(Self { index, count })
    }

    /// Whether test `test_index` belongs to this shard.
    pub fn contains(self, test_index: usize) -> bool {
        test_index % self.count == self.index - 1
    }

    /// The test indices of this shard among `tests` tests, in order.
    pub fn tests(self, tests: usize) -> impl Iterator<Item = usize> {
        (self.index - 1..tests).step_by(self.count)
    }

    /// Every shard of a campaign split `count` ways.
    pub fn all(count: usize) -> impl Iterator<Item = Self> {
        (1..=count).map(move |index| Self { index, count })
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = ShardError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let syntax = || ShardError::Syntax(text.to_owned());
        let (k, n) = text.trim().split_once('/').ok_or_else(syntax)?;
        let k: usize = k.trim().parse().map_err(|_| syntax())?;
        let n: usize = n.trim().parse().map_err(|_| syntax())?;
        Self::new(k, n).map_err(|_| ShardError::Range(text.to_owned()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn shards_parse_and_refuse_what_is_not_k_of_n() {
        assert_eq!("2/8".parse(), Ok(Shard { index: 2, count: 8 }));
        assert_eq!(" 1 / 1 ".parse(), Ok(Shard { index: 1, count: 1 }));
        for bad in ["", "2", "2/", "/8", "a/8", "2/8/1", "-1/8", "2.0/8"] {
            assert!(
                matches!(bad.parse::<Shard>(), Err(ShardError::Syntax(_))),
                "{bad}"
            );
        }
        for bad in ["0/8", "9/8", "0/0", "1/0"] {
            assert!(
                matches!(bad.parse::<Shard>(), Err(ShardError::Range(_))),
                "{bad}"
            );
        }
        assert_eq!(Shard::new(3, 4).unwrap().to_string(), "3/4");
    }

    proptest! {
        /// Every test is in exactly one shard, and a shard's tests are the ones it contains.
        #[test]
        fn the_shards_partition_the_tests(tests in 0usize..300, count in 1usize..40) {
            let mut seen = vec![0; tests];
            for shard in Shard::all(count) {
                let mine: Vec<usize> = shard.tests(tests).collect();
                let contained: Vec<usize> = (0..tests).filter(|&i| shard.contains(i)).collect();
                prop_assert_eq!(&mine, &contained);
                for i in mine {
                    seen[i] += 1;
                }
            }
            prop_assert!(seen.iter().all(|&n| n == 1));
            let sizes: Vec<usize> = Shard::all(count).map(|s| s.tests(tests).count()).collect();
            let (min, max) = (sizes.iter().min().unwrap(), sizes.iter().max().unwrap());
            prop_assert!(max - min <= 1);
        }
    }
}
