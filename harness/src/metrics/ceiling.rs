//! The noise ceiling of a ranking run: how well two independent MuJoCo runs of the
//! same size would agree with each other.
//!
//! Why: a policy's MuJoCo rate over 50 episodes is itself an estimate. Even a perfect
//! world model, whose episodes are drawn exactly as MuJoCo's are, would agree with a
//! finite MuJoCo run only as well as a second MuJoCo run with other sampling noise
//! does. Knowing that ceiling tells whether a Pearson of 0.77 is far from the best
//! reachable at this many episodes, or near it. It is estimated without a second
//! run: each replicate draws two independent resamples of every policy's MuJoCo
//! episodes (with replacement, within the policy, so a difference of two draws has
//! the variance of a difference of two runs) and computes the agreement of the two
//! sets of means. A policy whose episodes all score the same contributes no noise
//! here, so the ceiling is optimistic where rates are near 0 or 1.

use serde::{Deserialize, Serialize};

use super::agreement;
use super::bootstrap::{Stream, percentile};
use crate::seed::derive;

/// Agreement between two resampled MuJoCo runs of a run's size, over the replicates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseCeiling {
    /// Mean Pearson r (over replicates where it is defined).
    pub pearson: Option<f64>,
    /// Its 2.5 and 97.5 percentiles.
    pub pearson_ci95: Option<[f64; 2]>,
    /// Mean rank inversions.
    pub rank_inversions: f64,
    /// Mean of the mean absolute error over policies.
    pub mean_abs_error: f64,
    /// Replicates drawn.
    pub replicates: usize,
}

impl NoiseCeiling {
    /// The mean Pearson r with its interval, `0.974 [0.937, 0.994]` (`n/a` where r was
    /// never defined), as the stdout line and the report state it.
    pub fn pearson_text(&self) -> String {
        let r = self.pearson.map_or("n/a".to_string(), |r| format!("{r:.3}"));
        self.pearson_ci95.map_or(r.clone(), |[lo, hi]| format!("{r} [{lo:.3}, {hi:.3}]"))
    }
}

/// The resampled mean of `v` (0 when empty).
fn resampled_mean(v: &[f64], s: &mut Stream) -> f64 {
    let n = v.len();
    (0..n).map(|_| v[s.below(n)]).sum::<f64>() / n.max(1) as f64
}

/// The noise ceiling of per-policy MuJoCo episode scores (`actual[i]`: policy i's
/// episodes) over `b` seeded replicates; `None` below 2 policies, for a policy without
/// episodes, or for `b` = 0.
pub fn noise_ceiling(actual: &[Vec<f64>], b: usize, seed: u64) -> Option<NoiseCeiling> {
    if actual.len() < 2 || b == 0 || actual.iter().any(Vec::is_empty) {
        return None;
    }
    let mut s = Stream(derive(seed, &[0x6365_696c])); // "ceil"
    let (mut rs, mut inversions, mut mae) = (Vec::new(), 0.0, 0.0);
    for _ in 0..b {
        let x: Vec<f64> = actual.iter().map(|v| resampled_mean(v, &mut s)).collect();
        let y: Vec<f64> = actual.iter().map(|v| resampled_mean(v, &mut s)).collect();
        let m = agreement(&x, &y);
        rs.extend(m.pearson);
        inversions += m.rank_inversions.count as f64;
        mae += m.mean_abs_error;
    }
    let mean_r = (!rs.is_empty()).then(|| rs.iter().sum::<f64>() / rs.len() as f64);
    let ci = percentile(&mut rs, 0.025).zip(percentile(&mut rs, 0.975)).map(|(lo, hi)| [lo, hi]);
    Some(NoiseCeiling {
        pearson: mean_r,
        pearson_ci95: ci,
        rank_inversions: inversions / b as f64,
        mean_abs_error: mae / b as f64,
        replicates: b,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn policies_without_episode_noise_agree_perfectly() {
        // Every episode of policy i scores i/4: every resample gives the same means, so
        // r = 1, no inversion and no error in every replicate.
        let actual: Vec<Vec<f64>> = (0..4).map(|i| vec![i as f64 / 4.0; 5]).collect();
        let c = noise_ceiling(&actual, 50, 3).unwrap();
        assert_eq!(c.pearson, Some(1.0));
        assert_eq!(c.pearson_ci95, Some([1.0, 1.0]));
        assert_eq!(c.pearson_text(), "1.000 [1.000, 1.000]");
        assert_eq!((c.rank_inversions, c.mean_abs_error, c.replicates), (0.0, 0.0, 50));
    }

    #[test]
    fn the_error_of_two_draws_matches_its_expectation() {
        // Policy a never succeeds; policy b has episodes (0, 1). A resampled mean of b is
        // 0, 0.5 or 1 with probabilities 1/4, 1/2, 1/4. For two independent draws,
        // P(|x − y| = 0.5) = 4 · (1/4 · 1/2) = 1/2 and P(|x − y| = 1) = 2 · 1/16 = 1/8, so
        // E|x − y| = 0.25 + 0.125 = 0.375, and the MAE over the two policies is
        // (0 + 0.375) / 2 = 0.1875. The standard error over 20,000 replicates is about
        // 0.001.
        let c = noise_ceiling(&[vec![0.0, 0.0], vec![0.0, 1.0]], 20_000, 1).unwrap();
        assert!((c.mean_abs_error - 0.1875).abs() < 0.006, "{c:?}");
        // Over two policies r is ±1 where defined: it is undefined when a draw of b is 0
        // (both means 0), else +1, since b's mean is then above a's 0 in both runs.
        assert_eq!((c.pearson, c.pearson_ci95), (Some(1.0), Some([1.0, 1.0])));
        // b's draw is 0 with probability 1/4: r is undefined in those replicates (about
        // 7/16 have at least one such draw) and they do not count.
    }

    #[test]
    fn more_episodes_raise_the_ceiling_and_the_draws_are_seeded() {
        // Rates 0.3, 0.5, 0.7 from 10 or from 100 episodes each (exact fractions).
        let rates = |n: usize| -> Vec<Vec<f64>> {
            [3, 5, 7].iter().map(|&k| (0..n).map(|e| f64::from(u8::from(e * 10 < k * n))).collect()).collect()
        };
        let (few, many) = (rates(10), rates(100));
        let a = noise_ceiling(&few, 400, 9).unwrap();
        let b = noise_ceiling(&many, 400, 9).unwrap();
        assert!(b.pearson.unwrap() > a.pearson.unwrap(), "{a:?} {b:?}");
        assert!(b.mean_abs_error < a.mean_abs_error, "{a:?} {b:?}");
        assert_eq!(noise_ceiling(&few, 400, 9), Some(a.clone()));
        assert_ne!(noise_ceiling(&few, 400, 10), Some(a));
        assert_eq!(noise_ceiling(&few[..1], 400, 9), None, "one policy has no agreement");
        assert_eq!(noise_ceiling(&[vec![1.0], vec![]], 400, 9), None, "a policy without episodes");
    }
}
