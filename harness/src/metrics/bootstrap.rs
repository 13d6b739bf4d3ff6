//! Confidence intervals: Wilson score intervals for rates and a seeded,
//! paired, stratified bootstrap (rliable's scheme) for means and agreement metrics.
//!
//! The bootstrap resamples episodes with replacement *within each policy*, with
//! the same indices for the predicted and the actual episode scores (the two
//! branches of an episode are matched pairs), recomputes the per-policy means and
//! every metric, and reports the 2.5 and 97.5 percentiles (linear interpolation,
//! as numpy's default). Replicates where a metric is undefined are skipped for it.

use serde::Serialize;

use super::agreement;
use crate::seed::{derive, splitmix64};

/// Wilson score interval for `k` successes out of `n` at normal quantile `z` (1.96 for 95%).
///
/// ```
/// // 8 of 10: p = 0.8, z = 1.96 -> [0.4902, 0.9433] (Wilson 1927; e.g. statsmodels proportion_confint).
/// let (lo, hi) = harness::metrics::bootstrap::wilson(8, 10, 1.96);
/// assert!((lo - 0.4902).abs() < 1e-4 && (hi - 0.9433).abs() < 1e-4);
/// ```
pub fn wilson(k: usize, n: usize, z: f64) -> (f64, f64) {
    if n == 0 {
        return (0.0, 1.0);
    }
    let (k, n) = (k as f64, n as f64);
    let p = k / n;
    let z2 = z * z;
    let centre = p + z2 / (2.0 * n);
    let half = z * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt();
    let d = 1.0 + z2 / n;
    // At k = 0 (k = n) the lower (upper) bound is exactly 0 (1); the formula leaves
    // rounding residue there (2e-17 at 0 of 12), which reports would print.
    let lo = if k == 0.0 { 0.0 } else { ((centre - half) / d).max(0.0) };
    let hi = if k == n { 1.0 } else { ((centre + half) / d).min(1.0) };
    (lo, hi)
}

/// The `q`-quantile (0..=1) of `v` with linear interpolation (numpy's default); `None` if empty.
pub fn percentile(v: &mut [f64], q: f64) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let pos = q.clamp(0.0, 1.0) * (v.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    Some(v[lo] + (v[hi] - v[lo]) * (pos - lo as f64))
}

/// A seeded stream of uniform indices.
pub(crate) struct Stream(pub(crate) u64);

impl Stream {
    /// The next index in `0..n`.
    pub(crate) fn below(&mut self, n: usize) -> usize {
        self.0 = splitmix64(self.0);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64 * n as f64) as usize
    }
}

/// Percentile 95% interval of the mean of `values` over `b` seeded bootstrap replicates.
pub fn mean_ci(values: &[f64], b: usize, seed: u64) -> Option<[f64; 2]> {
    if values.is_empty() {
        return None;
    }
    let mut s = Stream(derive(seed, &[0x6d65_616e]));
    let n = values.len();
    let mut means: Vec<f64> =
        (0..b).map(|_| (0..n).map(|_| values[s.below(n)]).sum::<f64>() / n as f64).collect();
    Some([percentile(&mut means, 0.025)?, percentile(&mut means, 0.975)?])
}

/// Percentile 95% interval of the mean of all values in `clusters` over `b` seeded
/// replicates that resample whole clusters with replacement (the mean of each
/// replicate is over the values of the clusters it drew). For correlated values that
/// come in groups, such as overlapping video windows of one episode, where resampling
/// single values would make the interval too narrow. `None` without any value.
///
/// ```
/// // Two clusters with means 0.9 and 1.0 (1 and 3 values): every replicate's mean lies
/// // between 0.9 and 1.0, and the all-values mean (0.9 + 3) / 4 = 0.975 is inside.
/// let ci = harness::metrics::bootstrap::clustered_mean_ci(&[vec![0.9], vec![1.0; 3]], 500, 1).unwrap();
/// assert!(0.9 <= ci[0] && ci[0] <= 0.975 && 0.975 <= ci[1] && ci[1] <= 1.0, "{ci:?}");
/// ```
pub fn clustered_mean_ci(clusters: &[Vec<f64>], b: usize, seed: u64) -> Option<[f64; 2]> {
    let clusters: Vec<&Vec<f64>> = clusters.iter().filter(|c| !c.is_empty()).collect();
    if clusters.is_empty() {
        return None;
    }
    let mut s = Stream(derive(seed, &[0x63_6c75_7374_6572])); // "cluster"
    let n = clusters.len();
    let mut means: Vec<f64> = (0..b)
        .map(|_| {
            let (mut sum, mut count) = (0.0, 0usize);
            for _ in 0..n {
                let c = clusters[s.below(n)];
                sum += c.iter().sum::<f64>();
                count += c.len();
            }
            sum / count as f64
        })
        .collect();
    Some([percentile(&mut means, 0.025)?, percentile(&mut means, 0.975)?])
}

/// 95% intervals of every agreement metric.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct AgreementCi {
    /// Pearson r.
    pub pearson: Option<[f64; 2]>,
    /// Spearman ρ.
    pub spearman: Option<[f64; 2]>,
    /// Kendall τ_b.
    pub kendall_tau_b: Option<[f64; 2]>,
    /// Rank inversion count.
    pub rank_inversions: Option<[f64; 2]>,
    /// MMRV.
    pub mmrv: Option<[f64; 2]>,
    /// Regret@1.
    pub regret_at_1: Option<[f64; 2]>,
    /// Replicates drawn.
    pub replicates: usize,
}

/// Paired, stratified bootstrap of the agreement metrics. `policies[i]` holds policy i's
/// per-episode `(predicted, actual)` scores (equal lengths; episode e of both is a pair).
pub fn agreement_ci(policies: &[(Vec<f64>, Vec<f64>)], b: usize, seed: u64) -> AgreementCi {
    let mut s = Stream(derive(seed, &[0x6167_7265]));
    let mut cols: [Vec<f64>; 6] = Default::default();
    let mut pred = vec![0.0; policies.len()];
    let mut act = vec![0.0; policies.len()];
    for _ in 0..b {
        for (i, (p, a)) in policies.iter().enumerate() {
            let n = p.len().min(a.len());
            let (mut sp, mut sa) = (0.0, 0.0);
            for _ in 0..n {
                let e = s.below(n);
                sp += p[e];
                sa += a[e];
            }
            pred[i] = sp / n.max(1) as f64;
            act[i] = sa / n.max(1) as f64;
        }
        let m = agreement(&pred, &act);
        let vals = [
            m.pearson,
            m.spearman,
            m.kendall_tau_b,
            Some(m.rank_inversions.count as f64),
            Some(m.mmrv),
            Some(m.regret_at_1),
        ];
        for (col, v) in cols.iter_mut().zip(vals) {
            if let Some(v) = v {
                col.push(v);
            }
        }
    }
    let mut ci = |k: usize| -> Option<[f64; 2]> {
        let c = &mut cols[k];
        Some([percentile(c, 0.025)?, percentile(c, 0.975)?])
    };
    AgreementCi {
        pearson: ci(0),
        spearman: ci(1),
        kendall_tau_b: ci(2),
        rank_inversions: ci(3),
        mmrv: ci(4),
        regret_at_1: ci(5),
        replicates: b,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentile_interpolates_like_numpy() {
        // numpy.percentile([1, 2, 3, 4], 25) = 1.75; 97.5 -> 3.925.
        assert_eq!(percentile(&mut [4.0, 1.0, 3.0, 2.0], 0.25), Some(1.75));
        assert!((percentile(&mut [1.0, 2.0, 3.0, 4.0], 0.975).unwrap() - 3.925).abs() < 1e-12);
    }

    #[test]
    fn wilson_edges() {
        let (lo, hi) = wilson(0, 10, 1.96);
        assert_eq!(lo, 0.0);
        assert!((hi - 0.2775).abs() < 1e-4); // 0/10 -> [0, 0.2775]
        assert_eq!(wilson(0, 0, 1.96), (0.0, 1.0));
        // 0 of 12 and 12 of 12 are exact at their closed end (rank printed 2.1e-17 before).
        assert_eq!(wilson(0, 12, 1.96).0, 0.0);
        let (lo, hi) = wilson(12, 12, 1.96);
        assert!((lo - 0.7575).abs() < 1e-4 && hi == 1.0); // 12/12 -> [0.7575, 1]
    }

    #[test]
    fn bootstrap_is_seeded_and_brackets_the_point_estimate() {
        let policies: Vec<(Vec<f64>, Vec<f64>)> = (0..5)
            .map(|i| {
                let base = i as f64 / 5.0;
                let p: Vec<f64> = (0..20).map(|e| base + 0.05 * ((e * 7 % 5) as f64 - 2.0) / 2.0).collect();
                let a: Vec<f64> = p.iter().map(|v| v * 0.9 + 0.05).collect();
                (p, a)
            })
            .collect();
        let a = agreement_ci(&policies, 500, 7);
        // Actual = 0.9 pred + 0.05 per episode: every replicate has r = 1 exactly.
        let [lo, hi] = a.pearson.unwrap();
        assert!(lo > 0.999999 && hi <= 1.0);
        assert_eq!(a.rank_inversions, Some([0.0, 0.0]));
        let [mlo, mhi] = mean_ci(&[0.0, 1.0, 0.0, 1.0], 1000, 1).unwrap();
        assert!(mlo < 0.5 && mhi > 0.5);

        // Noisy pairs: the same seed gives the same intervals, another seed others.
        let mut z = 1u64;
        let mut noise = || {
            z = splitmix64(z);
            (z >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let noisy: Vec<(Vec<f64>, Vec<f64>)> = (0..5)
            .map(|i| {
                let p: Vec<f64> = (0..20).map(|_| i as f64 / 5.0 + 0.3 * noise()).collect();
                let a: Vec<f64> = (0..20).map(|_| i as f64 / 5.0 + 0.3 * noise()).collect();
                (p, a)
            })
            .collect();
        let c = agreement_ci(&noisy, 300, 7);
        assert_eq!(c, agreement_ci(&noisy, 300, 7));
        assert_ne!(c, agreement_ci(&noisy, 300, 8));
        let [lo, hi] = c.pearson.unwrap();
        assert!(lo < hi && hi <= 1.0);
    }
}
