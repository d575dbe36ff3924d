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
        neumaier_add(&mut self.sum, &mut self.comp, v);
    }

    #[inline]
    pub(crate) fn value(&self) -> f64 {
        self.sum + self.comp
    }
}

/// One step of [`Neumaier`] on a (sum, compensation) pair held elsewhere (per-order lanes of the
/// noise identification); its value is `sum + comp`.
#[inline]
pub(crate) fn neumaier_add(sum: &mut f64, comp: &mut f64, v: f64) {
    let t = *sum + v;
    // (big − t) + small, as selects rather than a branch (which mispredicts on noise)
    let (big, small) = if sum.abs() >= v.abs() {
        (*sum, v)
    } else {
        (v, *sum)
    };
    *comp += (big - t) + small;
    *sum = t;
}

/// Sum of squares of `f(i)` for `i in 0..n`: four independent lanes inside blocks of
/// [`crate::phase::BLOCK`] terms ([`block_sum_sq`]), block totals added with compensation (error
/// ≈ 256ε relative, in practice far less; the terms are all positive so there is no cancellation
/// to fear).
#[inline]
pub(crate) fn sum_sq(n: usize, mut f: impl FnMut(usize) -> f64) -> f64 {
    const BLOCK: usize = crate::phase::BLOCK;
    let mut total = Neumaier::default();
    let mut start = 0;
    while start < n {
        let end = (start + BLOCK).min(n);
        total.add(block_sum_sq(end - start, |i| f(start + i)));
        start = end;
    }
    total.value()
}

/// One block of [`sum_sq`]: Σ f(i)², i < `len`, in four lanes (i mod 4) added as
/// (l0 + l1) + (l2 + l3). The estimators call it on blocks read from memory or a file, so both
/// round alike.
#[inline]
pub(crate) fn block_sum_sq(len: usize, mut f: impl FnMut(usize) -> f64) -> f64 {
    let mut acc = [0.0f64; 4];
    let mut i = 0;
    while i + 4 <= len {
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
    while i < len {
        let a = f(i);
        acc[0] += a * a;
        i += 1;
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3])
}

/// Pairwise-free accurate mean: Neumaier sum divided by the count.
pub(crate) fn mean(values: &[f64]) -> f64 {
    let mut s = Neumaier::default();
    for &v in values {
        s.add(v);
    }
    s.value() / values.len() as f64
}
