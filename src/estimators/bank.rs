//! A bank of estimators fed one sample stream, so comparisons use common random numbers and
//! dynamic dispatch is paid per block, not per sample. Samples are validated here, once,
//! before any estimator sees them: a bad block is rejected whole and leaves every estimator
//! exactly as it was.

use super::{Estimator, EstimatorSpec};
use crate::error::{Error, Result};

/// Checks that every sample is finite and non-negative; `first_index` is the stream position
/// of `samples[0]`, so the error names the sample's index in the whole stream.
pub fn validate_samples(samples: &[f64], first_index: u64) -> Result<()> {
    // One branch-free pass in the common case; locate the culprit only on failure.
    let all_valid = samples
        .iter()
        .fold(true, |ok, &s| ok & (0.0..f64::INFINITY).contains(&s));
    if all_valid {
        return Ok(());
    }
    let (i, &value) = samples
        .iter()
        .enumerate()
        .find(|(_, s)| !(**s >= 0.0 && s.is_finite()))
        .expect("the fold found an invalid sample");
    Err(Error::InvalidSample {
        index: first_index + i as u64,
        value,
    })
}

/// Many estimators over one validated sample stream.
pub struct Bank {
    estimators: Vec<Box<dyn Estimator>>,
    count: u64,
}

impl Bank {
    /// Builds one estimator per spec.
    pub fn new(specs: &[EstimatorSpec]) -> Result<Self> {
        let estimators = specs
            .iter()
            .map(EstimatorSpec::build)
            .collect::<Result<_>>()?;
        Ok(Bank {
            estimators,
            count: 0,
        })
    }

    /// Wraps already-built estimators (all must be empty).
    pub fn from_estimators(estimators: Vec<Box<dyn Estimator>>) -> Self {
        Bank {
            estimators,
            count: 0,
        }
    }

    /// Validates the block, then feeds it to every estimator. On error nothing is applied.
    pub fn push_slice(&mut self, samples: &[f64]) -> Result<()> {
        validate_samples(samples, self.count)?;
        for e in &mut self.estimators {
            e.push_slice(samples);
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
