//! A bank of estimators fed one sample stream, so comparisons use common random numbers and
//! dynamic dispatch is paid per block, not per sample. Samples are validated here, once,
//! before any estimator sees them: a bad block is rejected whole and leaves every estimator
//! exactly as it was.

use super::{Estimator, EstimatorSpec, Partition};
use crate::error::{Error, Result};

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

/// Many estimators over one validated sample stream.
///
/// Estimators that keep one round-robin partition with the same number of sets (MoN, Gini,
/// G-MoN and G-MoN_b at one M) see the same sets, so the Bank feeds one partition per such M
/// and each of them copies it ([`Estimator::push_slice_sharing`]): 16 bytes a set per block
/// instead of a compensated add per sample each. Blocks shorter than M go to every estimator
/// directly, where the copy would cost more than the adds.
pub struct Bank {
    estimators: Vec<Box<dyn Estimator>>,
    /// One partition per number of sets that at least two estimators keep.
    shared: Vec<Partition>,
    /// Per estimator, the index in `shared` of the partition it adopts.
    adopts: Vec<Option<usize>>,
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
        let sets: Vec<Option<usize>> = estimators.iter().map(|e| e.partition_sets()).collect();
        let mut shared: Vec<Partition> = Vec::new();
        let adopts = sets
            .iter()
            .map(|&m| {
                let m = m.filter(|&m| sets.iter().filter(|&&k| k == Some(m)).count() >= 2)?;
                let at = shared
                    .iter()
                    .position(|p| p.sets() == m)
                    .unwrap_or_else(|| {
                        shared.push(Partition::new(m).expect("an estimator already keeps M sets"));
                        shared.len() - 1
                    });
                Some(at)
            })
            .collect();
        Bank {
            estimators,
            shared,
            adopts,
            count: 0,
        }
    }

    /// Validates the block, then feeds it to every estimator. On error nothing is applied.
    pub fn push_slice(&mut self, samples: &[f64]) -> Result<()> {
        validate_samples(samples, self.count)?;
        for p in &mut self.shared {
            p.push_slice(samples);
        }
        for (e, adopt) in self.estimators.iter_mut().zip(&self.adopts) {
            match adopt.map(|i| &self.shared[i]) {
                Some(p) if samples.len() >= p.sets() => e.push_slice_sharing(samples, p),
                _ => e.push_slice(samples),
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

    /// Total per-pixel state of the bank's estimators and shared partitions, in bytes.
    pub fn state_bytes(&self) -> usize {
        let shared: usize = self
            .shared
            .iter()
            .map(|p| std::mem::size_of::<Partition>() + p.heap_bytes())
            .sum();
        self.estimators
            .iter()
            .map(|e| e.state_bytes())
            .sum::<usize>()
            + shared
    }

    /// Forgets every sample, keeping the estimators and their allocations.
    pub fn reset(&mut self) {
        self.estimators.iter_mut().for_each(|e| e.reset());
        self.shared.iter_mut().for_each(Partition::reset);
        self.count = 0;
    }
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
        // Three estimators at M = 3 share one partition, the lone M = 5 keeps its own. Blocks
        // of every length around M (the short ones bypass the sharing) give estimates, extras
        // and counts equal bit for bit to estimators fed alone; a copy that lagged a block,
        // skipped the cursor or the count would change the sets' means.
        let texts = [
            "mon:M=3",
            "gini:M=3",
            "gmonb:M=3,threshold=0",
            "mon:M=5",
            "mean",
        ];
        let specs: Vec<EstimatorSpec> = texts.iter().map(|s| s.parse().unwrap()).collect();
        let mut bank = Bank::new(&specs).unwrap();
        assert_eq!(bank.shared.len(), 1);
        assert_eq!(bank.adopts, [Some(0), Some(0), Some(0), None, None]);
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
