//! Compensated summation and running moments shared by the estimators.

/// Neumaier's compensated sum (spec §1): exact to about one rounding for long streams of
/// samples that differ in magnitude by many decades, where a naive sum loses the small ones.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Neumaier {
    sum: f64,
    compensation: f64,
}

impl Neumaier {
    /// An empty sum.
    pub const fn new() -> Self {
        Neumaier {
            sum: 0.0,
            compensation: 0.0,
        }
    }

    /// Adds `x`, carrying the low-order bits lost by the naive sum into the compensation.
    #[inline(always)]
    pub fn add(&mut self, x: f64) {
        let t = self.sum + x;
        if self.sum.abs() >= x.abs() {
            self.compensation += (self.sum - t) + x;
        } else {
            self.compensation += (x - t) + self.sum;
        }
        self.sum = t;
    }

    /// The compensated total `s + c`.
    #[inline]
    pub fn value(&self) -> f64 {
        self.sum + self.compensation
    }

    /// Adds another compensated sum (for merging partial sums).
    pub fn merge(&mut self, other: &Neumaier) {
        self.add(other.sum);
        self.add(other.compensation);
    }
}

/// Welford's running mean and population variance (spec §1), mergeable with Chan et al.'s rule.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Welford {
    count: u64,
    mean: f64,
    m2: f64,
}

impl Welford {
    /// No observations.
    pub const fn new() -> Self {
        Welford {
            count: 0,
            mean: 0.0,
            m2: 0.0,
        }
    }

    /// Adds one observation in the spec's exact operation order.
    #[inline(always)]
    pub fn push(&mut self, x: f64) {
        self.count += 1;
        let d = x - self.mean;
        self.mean += d / self.count as f64;
        self.m2 += d * (x - self.mean);
    }

    /// Number of observations.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Running mean (0 with no observation).
    pub fn mean(&self) -> f64 {
        self.mean
    }

    /// Population standard deviation `sqrt(m2 / k)`: 0 with no observation, `+inf` once `m2`
    /// has overflowed.
    pub fn sigma(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            (self.m2 / self.count as f64).sqrt()
        }
    }

    /// Combines two accumulators as if all observations had gone through one.
    pub fn merge(&mut self, other: &Welford) {
        if other.count == 0 {
            return;
        }
        if self.count == 0 {
            *self = *other;
            return;
        }
        let n = (self.count + other.count) as f64;
        let d = other.mean - self.mean;
        self.mean += d * other.count as f64 / n;
        self.m2 += other.m2 + d * d * (self.count as f64) * (other.count as f64) / n;
        self.count += other.count;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn neumaier_keeps_small_terms_a_naive_sum_drops() {
        let mut s = Neumaier::new();
        s.add(1e100);
        s.add(1.0);
        s.add(-1e100);
        assert_eq!(s.value(), 1.0);
    }

    #[test]
    fn welford_sigma_of_running_example() {
        let mut w = Welford::new();
        for x in [0.6, 1.5, 0.0, 2.2, 4.8, 350.0, 4.1] {
            w.push(x);
        }
        assert!((w.sigma() - 121.71536384499028).abs() < 1e-12 * 121.7);
    }

    #[test]
    fn welford_merge_matches_single_pass() {
        let xs = [3.0, 1.0, 4.0, 1.0, 5.0, 9.0, 2.0, 6.0];
        let mut all = Welford::new();
        xs.iter().for_each(|&x| all.push(x));
        let (mut a, mut b) = (Welford::new(), Welford::new());
        xs[..3].iter().for_each(|&x| a.push(x));
        xs[3..].iter().for_each(|&x| b.push(x));
        a.merge(&b);
        assert_eq!(a.count(), all.count());
        assert!((a.mean() - all.mean()).abs() < 1e-14);
        assert!((a.sigma() - all.sigma()).abs() < 1e-14);
    }
}
