//! Which averaging factors m (τ = m·τ0) to evaluate.

/// A set of averaging times. The integer averaging factors follow allantools' `tau_generator`
/// applied to the phase record of N+1 points: only `0 < m < N+1` are kept, sorted, without
/// duplicates (an estimator then drops the factors that leave fewer than two terms, as
/// allantools' `remove_small_ns`).
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TauSet {
    /// m = 1, 2, 4, …, 2^⌊log₂(N+1)⌋ (the default: the closest-to-independent set).
    #[default]
    Octave,
    /// m = 1, 2, 4, 10, 20, 40, 100, … up to 4·10^⌊log₁₀(N+1)⌋ (allantools' and Stable32's
    /// "decade").
    Decade,
    /// `n` log-spaced factors per decade: m = round(10^(k/n)), k = 0, 1, …, duplicates removed
    /// (so the first decade holds fewer than `n` when `n` > 10). Not allantools' "log10", whose
    /// spacing depends on N.
    PerDecade(u32),
    /// Every m = 1, 2, 3, … (slow on long records: O(N²)).
    All,
    /// Explicit averaging times in seconds, rounded to the nearest multiple of τ0.
    Explicit(Vec<f64>),
}

impl TauSet {
    /// The averaging factors for a record of `n` rate samples (N+1 phase points) at `tau0_s`.
    pub fn factors(&self, n: usize, tau0_s: f64) -> Vec<usize> {
        let n_phase = n + 1;
        let mut m: Vec<usize> = match self {
            TauSet::Octave => {
                let maxn = n_phase.ilog2();
                (0..=maxn).map(|k| 1usize << k).collect()
            }
            TauSet::Decade => {
                let maxn = n_phase.ilog10();
                let mut v = Vec::new();
                let mut p = 1usize;
                for _ in 0..=maxn {
                    v.extend([p, 2 * p, 4 * p]);
                    p = p.saturating_mul(10);
                }
                v
            }
            TauSet::PerDecade(per) => {
                let per = (*per).max(1) as f64;
                let mut v = Vec::new();
                for k in 0u32.. {
                    let x = 10f64.powf(f64::from(k) / per).round();
                    if x >= n_phase as f64 || x.is_nan() {
                        break;
                    }
                    v.push(x as usize);
                }
                v
            }
            TauSet::All => (1..n_phase).collect(),
            TauSet::Explicit(taus) => taus
                .iter()
                .filter(|t| t.is_finite() && **t > 0.0)
                .map(|t| (t / tau0_s).round())
                .filter(|m| *m >= 1.0 && *m < n_phase as f64)
                .map(|m| m as usize)
                .collect(),
        };
        m.retain(|&m| m > 0 && m < n_phase);
        m.sort_unstable();
        m.dedup();
        m
    }
}
