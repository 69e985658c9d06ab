//! The seed map: every random stream of drivecheck, derived from one seed, and the one random
//! number generator they use.
//!
//! A campaign has one seed `s`; every random stream of it (and of the commands that drive a case
//! again) is derived from `s` here and nowhere else, by purpose. `γ` is SplitMix64's increment
//! `0x9E37_79B9_7F4A_7C15`, `mix` its output function; all arithmetic wraps.
//!
//! | purpose | from | seed | seeds |
//! |---|---|---|---|
//! | plan ([`plan_seed`]) | `s`, test `i` | 32 bytes: four SplitMix64 outputs (state `mix(mix(s) ^ i)`, `+ γ` before each), little-endian | proptest's ChaCha `TestRng` of test `i`'s plan (`model::TestPlanner`) |
//! | segment points | the plan | the `intent.seed` the plan draws for each segment (recorded in the case) | `trajgen`'s generator for that segment (`rng(intent.seed)`) |
//! | [`Purpose::Reset`] | `s`, test `i` | bytes 0..8 of the plan seed, little-endian | the return route before test `i` (orchestrator `runner::reset`) |
//! | [`Purpose::SafeStop`] | `s`, test `i` | bytes 24..32 of the plan seed, little-endian | test `i`'s safe stop extension (`drive::TestDrive`) |
//! | [`Purpose::Simulator`] | `s`, test `i` | `mix(s ^ (i + 1)·γ)` | test `i`'s fresh embedded simulated car (orchestrator `commands::shared::EmbeddedSims`) |
//! | simulator noise | the simulator's seed `m` | `m ^ n·γ`, stream `n` = 1 GNSS, 2 UWB, 3 link | `car_sim`'s `Noise` streams (`car-sim` is below this crate and keeps this line) |
//! | [`Purpose::Rerun`] | `s`, test `i`, run `k` | `k = 0`: the [`Purpose::Simulator`] seed `m` of test `i`; `k ≥ 1`: `mix(mix(m) ^ k)` | the simulated car of run `k` of test `i` driven again: run 0 is the campaign's own car (a replay, a shrink's first run), runs `k ≥ 1` other cars (a replay's `--vary-seed` runs 1…N, a shrink's other runs and its confirmation) |
//! | [`Purpose::StartJoin`] | `s` | `s` | the join from the recovery route to the start route, planned once per campaign |
//! | [`Purpose::Margins`] | `s` | `s` | ahead margins added to a case that has none (replay, shrink candidates) |
//! | [`Purpose::ShrinkJoin`] | `s` | `s` | the routes a shrink joins segments with (`shrink::Edit::DropSegments`) |
//! | [`Purpose::Run`] | `s`, run `k` (from 0) | `s + k` | the campaign seed of run `k` of a case without a campaign (hand-written: a replay's runs with `--vary-seed`, a shrink's candidate runs, its confirmation continuing at `k = runs`), a sweep's point, an explanation's counterfactual |
//! | [`Purpose::Calibration`] | `s` | `mix(s ^ 0xCA1B)` | the campaign seed of a case's runs in `calibrate` (its runs `k` then as [`Purpose::Run`]): the same for every candidate profile, other than a replay's or a twin check's |
//! | [`Purpose::FidelityRerun`] | `s`, rerun `k` | `s + k·1_000_003` | `bench fidelity`'s reruns of a test on other simulators and its route-following runs |
//! | [`Purpose::PlacementSim`] | `s`, link seed `l` | `s·1_000_003 + l` | `bench placement`'s simulators (the link's draws differ per link seed) |
//! | [`Purpose::RecoveryPose`] | `s`, pose `i` | `s + i` | `bench recovery`'s return route from pose `i` |
//!
//! The commands with a seed of their own that no campaign shares (`area validate`, `route
//! generate`, `route return`, `bench generator`, `bench recovery`'s poses, `sim`, `compare`'s
//! bootstrap) seed [`rng`]
//! (or the simulator) with it directly.
//!
//! The derivations are part of what a case file and a recording mean: changing one changes every
//! campaign of every seed. The tests below pin their values.

use rand::SeedableRng;

/// The random number generator of every drivecheck run: small, fast, portable and reproducible
/// across platforms for a given seed.
pub type RunRng = rand_pcg::Pcg64Mcg;

/// The run's generator for `seed`.
pub fn rng(seed: u64) -> RunRng {
    RunRng::seed_from_u64(seed)
}

/// The generator of `purpose` for the seed `seed`: `rng(derive(seed, purpose))`.
pub fn rng_for(seed: u64, purpose: Purpose) -> RunRng {
    rng(derive(seed, purpose))
}

/// What a derived seed is for (see the module doc's table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Purpose {
    /// The return route before a test.
    Reset {
        /// The test.
        test_index: usize,
    },
    /// A test's safe stop extension.
    SafeStop {
        /// The test.
        test_index: usize,
    },
    /// A test's fresh embedded simulated car.
    Simulator {
        /// The test.
        test_index: usize,
    },
    /// The simulated car of run `run` of test `test_index` driven again: run 0 is the car the
    /// campaign drove the test on ([`Purpose::Simulator`]), every later run another car.
    Rerun {
        /// The test.
        test_index: usize,
        /// The run, from 0 (the campaign's car).
        run: u64,
    },
    /// The join from the recovery route to the start route (once per campaign).
    StartJoin,
    /// Ahead margins generated for a case's segments that have none.
    Margins,
    /// A shrink's joining routes.
    ShrinkJoin,
    /// Run `run` (from 0) of a case driven again as a campaign of its own: a hand-written case's
    /// replay with `--vary-seed` and shrink, a sweep, an explanation's counterfactual.
    Run {
        /// The run, from 0.
        run: u64,
    },
    /// The runs of a case in `calibrate`.
    Calibration,
    /// A rerun of `bench fidelity`.
    FidelityRerun {
        /// The rerun, from 0 (rerun 0 is the seed itself).
        rerun: u64,
    },
    /// A simulator of `bench placement`.
    PlacementSim {
        /// The link seed.
        link_seed: u64,
    },
    /// `bench recovery`'s return route from one pose.
    RecoveryPose {
        /// The pose.
        pose: usize,
    },
}

/// The seed of `purpose` derived from `seed` (see the module doc's table).
pub fn derive(seed: u64, purpose: Purpose) -> u64 {
    match purpose {
        Purpose::Reset { test_index } => plan_seed_word(seed, test_index, 0),
        Purpose::SafeStop { test_index } => plan_seed_word(seed, test_index, 3),
        Purpose::Simulator { test_index } => {
            splitmix64_mix(seed ^ (test_index as u64).wrapping_add(1).wrapping_mul(GAMMA))
        }
        Purpose::Rerun { test_index, run } => {
            let car = derive(seed, Purpose::Simulator { test_index });
            if run == 0 {
                car
            } else {
                splitmix64_mix(splitmix64_mix(car) ^ run)
            }
        }
        Purpose::StartJoin | Purpose::Margins | Purpose::ShrinkJoin => seed,
        Purpose::Run { run } => seed.wrapping_add(run),
        Purpose::Calibration => splitmix64_mix(seed ^ 0xCA1B),
        Purpose::FidelityRerun { rerun } => seed.wrapping_add(rerun.wrapping_mul(1_000_003)),
        Purpose::PlacementSim { link_seed } => seed.wrapping_mul(1_000_003).wrapping_add(link_seed),
        Purpose::RecoveryPose { pose } => seed.wrapping_add(pose as u64),
    }
}

/// The 32-byte seed of proptest's ChaCha RNG for test `test_index` of a campaign with `seed`:
/// four SplitMix64 outputs from a state mixing both.
pub fn plan_seed(seed: u64, test_index: usize) -> [u8; 32] {
    let mut state = splitmix64_mix(splitmix64_mix(seed) ^ test_index as u64);
    let mut bytes = [0u8; 32];
    for chunk in bytes.chunks_exact_mut(8) {
        state = state.wrapping_add(GAMMA);
        chunk.copy_from_slice(&splitmix64_mix(state).to_le_bytes());
    }
    bytes
}

/// Word `word` (0–3) of the plan seed, little-endian.
fn plan_seed_word(seed: u64, test_index: usize, word: usize) -> u64 {
    let bytes = plan_seed(seed, test_index);
    let mut out = [0u8; 8];
    out.copy_from_slice(&bytes[word * 8..word * 8 + 8]);
    u64::from_le_bytes(out)
}

/// SplitMix64's increment (the golden ratio's fraction in 64 bits).
const GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64's output function.
fn splitmix64_mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(bytes: &[u8]) -> String {
        bytes.iter().map(|b| format!("{b:02x}")).collect()
    }

    /// The values every case file and recording so far was made with (computed independently
    /// of this code): a derivation must never change.
    #[test]
    fn the_derived_seeds_are_the_ones_campaigns_were_recorded_with() {
        let pinned = [
            (
                7,
                0,
                "0b4ccfcf1d0aadb42a1a648cc05cd26faef71107f151dfdbe19f613cc61a3874",
                0xb4ad_0a1d_cfcf_4c0b,
                0x7438_1ac6_3c61_9fe1,
                0xf75f_04cb_b5a1_a1dd,
            ),
            (
                7,
                1,
                "2a6aabd60969bf64fdfb8d77887a27ff7c9fbe44ae9387954368ebd1ed6b1a6a",
                0x64bf_6909_d6ab_6a2a,
                0x6a1a_6bed_d1eb_6843,
                0xb346_6f8a_7b81_a989,
            ),
            (
                1,
                3,
                "91a7aabf6dbb8b52ec96bd5e9c78ee8f78ff44a04f2a6ac84dcb7774936df08a",
                0x528b_bb6d_bfaa_a791,
                0x8af0_6d93_7477_cb4d,
                0x71c1_8690_ee42_c90b,
            ),
            (
                0xDEAD_BEEF,
                41,
                "a85635b7af20281e3bb0c9a54817bebe296be2578de36ec5dc7109b4bb61b52e",
                0x1e28_20af_b735_56a8,
                0x2eb5_61bb_b409_71dc,
                0xa024_0fd9_b274_f954,
            ),
        ];
        for (seed, test_index, plan, reset, stop, sim) in pinned {
            assert_eq!(
                hex(&plan_seed(seed, test_index)),
                plan,
                "{seed}/{test_index}"
            );
            assert_eq!(derive(seed, Purpose::Reset { test_index }), reset);
            assert_eq!(derive(seed, Purpose::SafeStop { test_index }), stop);
            assert_eq!(derive(seed, Purpose::Simulator { test_index }), sim);
        }
    }

    #[test]
    fn the_arithmetic_purposes_are_as_the_table_says() {
        let s = u64::MAX - 1;
        assert_eq!(derive(s, Purpose::StartJoin), s);
        assert_eq!(derive(s, Purpose::Margins), s);
        assert_eq!(derive(s, Purpose::ShrinkJoin), s);
        assert_eq!(derive(s, Purpose::Run { run: 0 }), s);
        assert_eq!(derive(s, Purpose::Run { run: 3 }), 1); // wraps
        assert_eq!(derive(10, Purpose::FidelityRerun { rerun: 2 }), 2_000_016);
        assert_eq!(
            derive(10, Purpose::Calibration),
            splitmix64_mix(10 ^ 0xCA1B)
        );
        assert_eq!(
            derive(10, Purpose::PlacementSim { link_seed: 4 }),
            10_000_034
        );
        assert_eq!(derive(10, Purpose::RecoveryPose { pose: 5 }), 15);
        // The generator of a purpose is the run's generator of its derived seed.
        use rand::RngExt;
        let purpose = Purpose::SafeStop { test_index: 2 };
        assert_eq!(
            rng_for(9, purpose).random::<u64>(),
            rng(derive(9, purpose)).random::<u64>()
        );
    }

    #[test]
    fn a_rerun_starts_on_the_campaigns_car_and_then_drives_other_cars() {
        let rerun = |run| derive(7, Purpose::Rerun { test_index: 3, run });
        let car = derive(7, Purpose::Simulator { test_index: 3 });
        assert_eq!(rerun(0), car);
        assert_eq!(rerun(1), splitmix64_mix(splitmix64_mix(car) ^ 1));
        let others: std::collections::BTreeSet<u64> = (1..100).map(rerun).collect();
        assert_eq!(others.len(), 99);
        assert!(!others.contains(&car));
        // No other test's campaign car either.
        assert!(
            (0..100).all(|i| !others.contains(&derive(7, Purpose::Simulator { test_index: i })))
        );
    }

    #[test]
    fn tests_and_campaigns_get_streams_of_their_own() {
        let a = plan_seed(7, 0);
        assert_ne!(a, plan_seed(7, 1));
        assert_ne!(a, plan_seed(8, 0));
        let sim = |s, i| derive(s, Purpose::Simulator { test_index: i });
        assert_ne!(sim(7, 0), sim(7, 1));
        assert_ne!(sim(7, 0), sim(8, 0));
        assert_ne!(
            derive(7, Purpose::Reset { test_index: 0 }),
            derive(7, Purpose::SafeStop { test_index: 0 })
        );
    }
}
