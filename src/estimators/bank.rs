//! A bank of estimators fed one sample stream, so comparisons use common random numbers and
//! dynamic dispatch is paid per block, not per sample. Samples are validated here, once,
//! before any estimator sees them: a bad block is rejected whole and leaves every estimator
//! exactly as it was.

use super::rgb::for_each_chunk;
use super::{Estimator, EstimatorSpec, Partition, RgbEstimator};
use crate::error::{Error, Result};
use std::sync::Arc;

/// Checks that every sample is finite and non-negative; `first_index` is the stream position
/// of `samples[0]`, so the error names the sample's index in the whole stream.
pub fn validate_samples(samples: &[f64], first_index: u64) -> Result<()> {
    // One branch-free pass in the common case, in float lanes that vectorise: `x * 0` is NaN
    // exactly when `x` is NaN or infinite (and NaN then stays in the lane's sum), and the lane
    // minimum (from 0) is negative exactly when some `x < 0`. Locate the culprit only on failure.
    let (mut probe, mut lowest) = ([0.0f64; 8], [0.0f64; 8]);
    let blocks = samples.chunks_exact(8);
    let rest = blocks.remainder();
    for block in blocks {
        for ((p, low), &x) in probe.iter_mut().zip(&mut lowest).zip(block) {
            *p += x * 0.0;
            *low = if x < *low { x } else { *low };
        }
    }
    let lanes_valid = probe
        .iter()
        .zip(&lowest)
        .all(|(&p, &low)| p == 0.0 && low >= 0.0);
    let valid = |s: f64| s >= 0.0 && s.is_finite();
    if lanes_valid && rest.iter().all(|&s| valid(s)) {
        return Ok(());
    }
    let (i, &value) = samples
        .iter()
        .enumerate()
        .find(|&(_, &s)| !valid(s))
        .expect("the fold found an invalid sample");
    Err(Error::InvalidSample {
        index: first_index + i as u64,
        value,
    })
}

/// Where an estimator finds the partition it adopts: an earlier estimator and the index in
/// its [`Estimator::partitions`].
type Leader = (usize, usize);

/// The sharing rule of [`Bank`] and [`RgbBank`]: an estimator that keeps exactly one partition
/// (`sets[i]` lists the set counts of estimator `i`'s partitions) adopts the first partition
/// with as many sets that an earlier estimator keeps (a MoN family member's, or one of Jung's),
/// instead of filling its own.
fn leaders(sets: &[Vec<usize>]) -> Vec<Option<Leader>> {
    sets.iter()
        .enumerate()
        .map(|(i, own)| {
            let &[m] = own.as_slice() else {
                return None;
            };
            sets[..i]
                .iter()
                .enumerate()
                .find_map(|(j, theirs)| Some((j, theirs.iter().position(|&k| k == m)?)))
        })
        .collect()
}

/// Many estimators over one validated sample stream.
///
/// Estimators that keep round-robin partitions with the same number of sets (MoN, Gini, G-MoN
/// and G-MoN_b at one M; Jung at every odd M up to its `m_max`) see the same sets, so only the
/// first of them (the leader) adds the samples; each later MoN-family estimator with that M
/// copies the leader's partition ([`Estimator::push_slice_sharing`]): 16 bytes a set per block
/// instead of a compensated add per sample each, and no state beyond the estimators' own.
/// Blocks shorter than M go to every estimator directly, where the copy would cost more than
/// the adds.
pub struct Bank {
    estimators: Vec<Box<dyn Estimator>>,
    /// Per estimator, where the partition it adopts is kept.
    adopts: Vec<Option<Leader>>,
    count: u64,
}

impl Bank {
    /// Builds one estimator per spec.
    pub fn new(specs: &[EstimatorSpec]) -> Result<Self> {
        let estimators = specs
            .iter()
            .map(EstimatorSpec::build)
            .collect::<Result<_>>()?;
        Ok(Self::from_estimators(estimators))
    }

    /// Wraps already-built estimators (all must be empty).
    pub fn from_estimators(estimators: Vec<Box<dyn Estimator>>) -> Self {
        let sets: Vec<Vec<usize>> = estimators
            .iter()
            .map(|e| e.partitions().iter().map(Partition::sets).collect())
            .collect();
        Bank {
            adopts: leaders(&sets),
            estimators,
            count: 0,
        }
    }

    /// Validates the block, then feeds it to every estimator, leaders before the estimators
    /// that adopt their partitions. On error nothing is applied.
    pub fn push_slice(&mut self, samples: &[f64]) -> Result<()> {
        validate_samples(samples, self.count)?;
        for i in 0..self.estimators.len() {
            let (done, rest) = self.estimators.split_at_mut(i);
            match self.adopts[i].map(|(l, k)| &done[l].partitions()[k]) {
                Some(p) if samples.len() >= p.sets() => rest[0].push_slice_sharing(samples, p),
                _ => rest[0].push_slice(samples),
            }
        }
        self.count += samples.len() as u64;
        Ok(())
    }

    /// Validates and feeds one sample.
    pub fn push(&mut self, sample: f64) -> Result<()> {
        self.push_slice(std::slice::from_ref(&sample))
    }

    /// Samples accepted so far.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The estimators, in the order given.
    pub fn estimators(&self) -> &[Box<dyn Estimator>] {
        &self.estimators
    }

    /// Every estimator's current estimate, in order.
    pub fn estimates(&self) -> Result<Vec<f64>> {
        self.estimators.iter().map(|e| e.estimate()).collect()
    }

    /// Total per-pixel state of the bank's estimators, in bytes.
    pub fn state_bytes(&self) -> usize {
        self.estimators.iter().map(|e| e.state_bytes()).sum()
    }

    /// Forgets every sample, keeping the estimators and their allocations.
    pub fn reset(&mut self) {
        self.estimators.iter_mut().for_each(|e| e.reset());
        self.count = 0;
    }
}

/// The film's bank: the RGB estimators of one pixel over its stream of RGB samples, with the
/// sharing rule of [`Bank`] applied per channel (the MoN family keeps one partition per
/// channel). Each block is split into channels once, in chunks of 64 samples, for all
/// per-channel estimators, and not at all when none reads the split (a bank of `mean` alone,
/// as the cross-check against Mitsuba renders). The specs and the sharing plan are the same
/// for every pixel, so banks made with [`RgbBank::empty_like`] share them: a pixel pays one
/// pointer for them.
pub struct RgbBank {
    estimators: Vec<Box<dyn RgbEstimator>>,
    plan: Arc<Plan>,
    count: u64,
}

/// What every pixel's [`RgbBank`] of the same specs has in common.
struct Plan {
    specs: Vec<EstimatorSpec>,
    /// Per estimator, where the three partitions it adopts are kept.
    adopts: Vec<Option<Leader>>,
    /// Whether some estimator reads the block split into channels (else the split is skipped).
    split: bool,
}

impl RgbBank {
    /// Builds one RGB estimator per spec.
    pub fn new(specs: &[EstimatorSpec]) -> Result<Self> {
        let estimators = build_rgb_all(specs)?;
        let sets: Vec<Vec<usize>> = estimators
            .iter()
            .map(|e| {
                e.channel_partitions()[0]
                    .iter()
                    .map(Partition::sets)
                    .collect()
            })
            .collect();
        let plan = Plan {
            specs: specs.to_vec(),
            adopts: leaders(&sets),
            split: estimators.iter().any(|e| e.reads_channels()),
        };
        Ok(RgbBank {
            estimators,
            plan: Arc::new(plan),
            count: 0,
        })
    }

    /// A bank of the same specs with no samples, sharing this one's plan.
    pub fn empty_like(&self) -> Result<Self> {
        Ok(RgbBank {
            estimators: build_rgb_all(&self.plan.specs)?,
            plan: Arc::clone(&self.plan),
            count: 0,
        })
    }

    /// Feeds the block to every estimator. As for [`RgbEstimator::push_slice`], the caller
    /// guarantees every channel is finite and non-negative: the film checks each sample as it
    /// is traced (to count and leave out the bad ones), so checking again here would be a
    /// second pass over every sample.
    pub fn push_slice(&mut self, samples: &[[f64; 3]]) {
        if self.plan.split {
            for_each_chunk(samples, |chunk, channels| {
                for i in 0..self.estimators.len() {
                    let (done, rest) = self.estimators.split_at_mut(i);
                    let shared = self.plan.adopts[i]
                        .map(|(l, k)| done[l].channel_partitions().map(|p| &p[k]))
                        .filter(|p| chunk.len() >= p[0].sets());
                    rest[0].push_channels(chunk, channels, shared);
                }
            });
        } else {
            for e in &mut self.estimators {
                e.push_slice(samples);
            }
        }
        self.count += samples.len() as u64;
    }

    /// Samples accepted so far.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The estimators, in the order given.
    pub fn estimators(&self) -> &[Box<dyn RgbEstimator>] {
        &self.estimators
    }

    /// Hands the image's per-channel `σ_image` to every estimator that reads it (Jung's image
    /// mode).
    pub fn set_image_sigma(&mut self, sigma: [f64; 3]) -> Result<()> {
        self.estimators
            .iter_mut()
            .try_for_each(|e| e.set_image_sigma(sigma))
    }

    /// Per-pixel bytes held beyond the bank's own struct: every estimator's state and its
    /// entry in the bank's list (the shared plan is not counted).
    pub fn state_bytes(&self) -> usize {
        self.estimators
            .iter()
            .map(|e| e.state_bytes() + size_of::<Box<dyn RgbEstimator>>())
            .sum()
    }
}

/// One RGB estimator per spec.
fn build_rgb_all(specs: &[EstimatorSpec]) -> Result<Vec<Box<dyn RgbEstimator>>> {
    specs.iter().map(EstimatorSpec::build_rgb).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn invalid_sample_is_named_with_stream_index() {
        let e = validate_samples(&[1.0, 0.0, f64::NAN], 10).unwrap_err();
        assert_eq!(e.to_string(), "invalid sample at index 12: NaN");
        let e = validate_samples(&[-1.0], 0).unwrap_err();
        assert_eq!(e.to_string(), "invalid sample at index 0: -1");
        let e = validate_samples(&[f64::INFINITY], 0).unwrap_err();
        assert_eq!(e.to_string(), "invalid sample at index 0: inf");
        assert!(validate_samples(&[0.0, -0.0, 1e300, 1e-300], 0).is_ok());
        // In the lanes and in the remainder after them, every kind of bad value.
        for bad in [f64::NAN, -1.0, f64::INFINITY, f64::NEG_INFINITY, -1e-300] {
            for at in [0, 7, 8, 13, 19] {
                let mut xs = vec![1.0; 20];
                xs[at] = bad;
                let e = validate_samples(&xs, 100).unwrap_err();
                assert!(
                    e.to_string().contains(&format!("index {}", 100 + at)),
                    "{e}"
                );
            }
        }
        assert!(validate_samples(&[2.0; 20], 0).is_ok());
    }

    #[test]
    fn estimators_with_one_m_share_a_partition_and_agree_with_their_own() {
        // Three estimators at M = 3 share one partition; M = 7 keeps its own (Jung, who also
        // keeps one, comes later); G-MoN at M = 9 and MoN at M = 5 copy Jung's. Blocks of
        // every length around M (the short ones bypass the sharing) give estimates, extras and
        // counts equal bit for bit to estimators fed alone; a copy that lagged a block, skipped
        // the cursor or the count, or took the wrong one of Jung's partitions would change the
        // sets' means.
        let texts = [
            "mon:M=3",
            "gini:M=3",
            "gmonb:M=3,threshold=0",
            "mon:M=7",
            "mean",
            "jung:sigma_image=1,m_max=9",
            "gmon:M=9",
            "mon:M=5",
        ];
        let specs: Vec<EstimatorSpec> = texts.iter().map(|s| s.parse().unwrap()).collect();
        let mut bank = Bank::new(&specs).unwrap();
        let (j, m3) = (Some((5, 4)), Some((0, 0)));
        assert_eq!(
            bank.adopts,
            [None, m3, m3, None, None, None, j, Some((5, 2))]
        );
        let mut alone: Vec<_> = specs.iter().map(|s| s.build().unwrap()).collect();
        let xs: Vec<f64> = (0..200u32).map(|i| f64::from(i * 7 % 13) * 0.5).collect();
        let mut rest = &xs[..];
        for len in [1, 2, 3, 4, 7, 1, 30, 2, 100].iter().cycle() {
            let block = &rest[..(*len).min(rest.len())];
            bank.push_slice(block).unwrap();
            alone.iter_mut().for_each(|e| e.push_slice(block));
            for (b, a) in bank.estimators().iter().zip(&alone) {
                assert_eq!(
                    b.estimate().unwrap().to_bits(),
                    a.estimate().unwrap().to_bits()
                );
                assert_eq!(b.extras(), a.extras(), "{a}");
                assert_eq!(b.count(), a.count());
            }
            rest = &rest[block.len()..];
            if rest.is_empty() {
                break;
            }
        }
        bank.reset();
        bank.push_slice(&xs[..9]).unwrap();
        let mut fresh = Bank::new(&specs).unwrap();
        fresh.push_slice(&xs[..9]).unwrap();
        assert_eq!(bank.estimates().unwrap(), fresh.estimates().unwrap());
    }

    #[test]
    fn rgb_bank_shares_per_channel_and_agrees_with_estimators_fed_alone() {
        // The MoN family at M = 3 adopts the first one's three partitions, MoN at M = 5 Jung's
        // third ones; Jung, Zirr and Pajot take the chunked channels or the RGB block. Blocks
        // of every length around M and around the 64-sample chunk (a chunk shorter than M
        // bypasses the sharing, and M = 300 never shares) give every channel's estimate bit for
        // bit as an estimator fed alone.
        // (The bank does not check samples: its caller, the film, does.)
        let texts = [
            "gini:M=3",
            "mean",
            "mon:M=3",
            "gmonb:M=3,threshold=0",
            "gmon:M=3",
            "mon:M=300",
            "jung:sigma_image=1",
            "mon:M=5",
            "zirr",
            "pajot-rot",
        ];
        let specs: Vec<EstimatorSpec> = texts.iter().map(|s| s.parse().unwrap()).collect();
        let mut bank = RgbBank::new(&specs).unwrap();
        assert_eq!(
            bank.plan.adopts,
            [
                None,
                None,
                Some((0, 0)),
                Some((0, 0)),
                Some((0, 0)),
                None,
                None,
                Some((6, 2)),
                None,
                None
            ]
        );
        let mut alone: Vec<_> = specs.iter().map(|s| s.build_rgb().unwrap()).collect();
        let xs: Vec<[f64; 3]> = (0..2000u32)
            .map(|i| {
                let v = f64::from(i * 7 % 13) * 0.5;
                [v, v * v, if i % 97 == 0 { 1e6 } else { 0.25 }]
            })
            .collect();
        let mut rest = &xs[..];
        for len in [1, 2, 3, 4, 65, 7, 1, 30, 63, 129, 100, 257].iter().cycle() {
            let block = &rest[..(*len).min(rest.len())];
            bank.push_slice(block);
            alone.iter_mut().for_each(|e| e.push_slice(block));
            for (b, a) in bank.estimators().iter().zip(&alone) {
                assert_eq!(
                    b.estimate().unwrap().map(f64::to_bits),
                    a.estimate().unwrap().map(f64::to_bits),
                    "{a}"
                );
                assert_eq!(b.count(), a.count());
            }
            rest = &rest[block.len()..];
            if rest.is_empty() {
                break;
            }
        }
        assert_eq!(bank.count(), 2000);
        // A bank made like this one starts empty, with the same estimators and plan.
        let mut like = bank.empty_like().unwrap();
        assert!(Arc::ptr_eq(&like.plan, &bank.plan));
        assert_eq!(like.count(), 0);
        like.push_slice(&xs[..100]);
        let mut fresh = RgbBank::new(&specs).unwrap();
        fresh.push_slice(&xs[..100]);
        for (a, b) in like.estimators().iter().zip(fresh.estimators()) {
            assert_eq!(a.to_string(), b.to_string());
            assert_eq!(a.estimate().unwrap(), b.estimate().unwrap());
        }
    }

    #[test]
    fn a_bad_block_leaves_the_bank_unchanged() {
        let specs: Vec<EstimatorSpec> = ["mean", "mon:M=3", "gmonb:M=3"]
            .iter()
            .map(|s| s.parse().unwrap())
            .collect();
        let mut bank = Bank::new(&specs).unwrap();
        bank.push_slice(&[1.0, 2.0, 3.0]).unwrap();
        let before = bank.estimates().unwrap();
        let e = bank.push_slice(&[4.0, f64::NEG_INFINITY, 5.0]).unwrap_err();
        assert_eq!(e.to_string(), "invalid sample at index 4: -inf");
        assert_eq!(bank.count(), 3);
        assert_eq!(bank.estimates().unwrap(), before);
        assert!(bank.estimators().iter().all(|e| e.count() == 3));
    }
}
