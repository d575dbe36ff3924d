//! Compensated summation helpers (the numerics behind the precision claims in the crate docs).

/// Neumaier-compensated running sum: error bounded by ~2ε·Σ|xᵢ| independent of the count.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Neumaier {
    sum: f64,
    comp: f64,
}

impl Neumaier {
    #[inline]
    pub(crate) fn add(&mut self, v: f64) {
        let t = self.sum + v;
        if self.sum.abs() >= v.abs() {
            self.comp += (self.sum - t) + v;
        } else {
            self.comp += (v - t) + self.sum;
        }
        self.sum = t;
    }

    #[inline]
    pub(crate) fn value(&self) -> f64 {
        self.sum + self.comp
    }
}

/// Sum of squares of `f(i)` for `i in 0..n`: four independent lanes inside blocks of 1024 terms,
/// block totals added with compensation (error ≈ 256ε relative, in practice far less; the terms
/// are all positive so there is no cancellation to fear).
#[inline]
pub(crate) fn sum_sq(n: usize, mut f: impl FnMut(usize) -> f64) -> f64 {
    const BLOCK: usize = 1024;
    let mut total = Neumaier::default();
    let mut start = 0;
    while start < n {
        let end = (start + BLOCK).min(n);
        let mut acc = [0.0f64; 4];
        let mut i = start;
        while i + 4 <= end {
            let a = f(i);
            let b = f(i + 1);
            let c = f(i + 2);
            let d = f(i + 3);
            acc[0] += a * a;
            acc[1] += b * b;
            acc[2] += c * c;
            acc[3] += d * d;
            i += 4;
        }
        while i < end {
            let a = f(i);
            acc[0] += a * a;
            i += 1;
        }
        total.add((acc[0] + acc[1]) + (acc[2] + acc[3]));
        start = end;
    }
    total.value()
}

/// Pairwise-free accurate mean: Neumaier sum divided by the count.
pub(crate) fn mean(values: &[f64]) -> f64 {
    let mut s = Neumaier::default();
    for &v in values {
        s.add(v);
    }
    s.value() / values.len() as f64
}
