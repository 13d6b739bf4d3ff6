//! Paired success: how one policy's episodes succeed in the two branches of a
//! ranking run, seed by seed.
//!
//! Why: both branches start from the same state, so a seed imagined succeeding that
//! fails in MuJoCo is the world model's (or its judge's) own error. A success rate
//! hides it wherever the reverse error on other seeds offsets it, and these counts
//! show it (`results.json`'s `policies[i].paired_success`, the report's table).

use serde::{Deserialize, Serialize};

/// One policy's seeds, counted by their success in MuJoCo and imagined.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PairedSuccess {
    /// Seeds that succeed in both branches.
    pub both: usize,
    /// Seeds imagined succeeding that fail in MuJoCo.
    pub imagined_only: usize,
    /// Seeds that succeed in MuJoCo and are imagined failing.
    pub sim_only: usize,
    /// Seeds that fail in both.
    pub neither: usize,
}

impl PairedSuccess {
    /// Counts the (MuJoCo, imagined) success of each seed.
    pub fn count(pairs: impl IntoIterator<Item = (bool, bool)>) -> Self {
        let mut c = Self::default();
        for (sim, wm) in pairs {
            match (sim, wm) {
                (true, true) => c.both += 1,
                (false, true) => c.imagined_only += 1,
                (true, false) => c.sim_only += 1,
                (false, false) => c.neither += 1,
            }
        }
        c
    }

    /// Seeds counted.
    pub fn seeds(&self) -> usize {
        self.both + self.imagined_only + self.sim_only + self.neither
    }

    /// Seeds on which the two branches agree, as a fraction (0 for none).
    pub fn agreement(&self) -> f64 {
        (self.both + self.neither) as f64 / self.seeds().max(1) as f64
    }

    /// Cohen's κ of the two branches' success over the seeds: 1 when the world model
    /// tells exactly which seeds succeed, about 0 when its outcome of a seed is
    /// independent of the real one (it then knows the policy's rate at best, not the
    /// episode). None when chance agreement is already certain (every seed succeeds,
    /// or every seed fails, in both branches), or without seeds.
    ///
    /// Computed from the counts in the 2 × 2 form κ = 2(ad − bc) / ((a+b)(b+d) + (a+c)(c+d))
    /// (a both, b MuJoCo only, c imagined only, d neither), which equals (observed −
    /// chance) / (1 − chance) and is exactly 0 when one branch never (or always)
    /// succeeds, with no rounding residue to print as −0.00.
    pub fn kappa(&self) -> Option<f64> {
        let [a, b, c, d] = [self.both, self.sim_only, self.imagined_only, self.neither].map(|v| v as f64);
        let denominator = (a + b) * (b + d) + (a + c) * (c + d);
        (denominator > 0.0).then(|| 2.0 * (a * d - b * c) / denominator)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_each_combination_and_the_agreement() {
        // (MuJoCo, imagined): (T, T), (F, T) twice, (T, F), (F, F) three times: both 1,
        // imagined only 2, MuJoCo only 1, neither 3; agreement (1 + 3) / 7 = 4/7.
        let (t, f) = (true, false);
        let c = PairedSuccess::count([(t, t), (f, t), (f, t), (t, f), (f, f), (f, f), (f, f)]);
        assert_eq!(c, PairedSuccess { both: 1, imagined_only: 2, sim_only: 1, neither: 3 });
        assert!((c.agreement() - 4.0 / 7.0).abs() < 1e-12);
        assert_eq!(PairedSuccess::count([]).agreement(), 0.0, "no seeds: 0, not NaN");
        // κ: MuJoCo rate 2/7, imagined 3/7; chance agreement 2/7·3/7 + 5/7·4/7 = 26/49;
        // observed 28/49; κ = (28/49 − 26/49) / (1 − 26/49) = 2/23.
        assert!((c.kappa().unwrap() - 2.0 / 23.0).abs() < 1e-12, "{:?}", c.kappa());
    }

    #[test]
    fn kappa_is_one_for_exact_outcomes_zero_for_independent_ones_and_none_when_certain() {
        // Every seed right: observed 1, κ 1.
        let exact = PairedSuccess { both: 3, imagined_only: 0, sim_only: 0, neither: 5 };
        assert!((exact.kappa().unwrap() - 1.0).abs() < 1e-12);
        // Rates 1/2 in both, and each imagined outcome splits evenly over the real ones:
        // observed 2/4 = chance 1/2·1/2 + 1/2·1/2 = 1/2, so κ = 0.
        let independent = PairedSuccess { both: 1, imagined_only: 1, sim_only: 1, neither: 1 };
        assert!(independent.kappa().unwrap().abs() < 1e-12);
        // MuJoCo never succeeds (a = b = 0): κ is exactly 0, not a rounding residue.
        let never = PairedSuccess { both: 0, imagined_only: 14, sim_only: 0, neither: 6 };
        assert_eq!(never.kappa().map(f64::to_bits), Some(0.0_f64.to_bits()));
        // Every seed succeeds in both branches: chance agreement is 1, κ undefined.
        assert_eq!(PairedSuccess { both: 4, ..Default::default() }.kappa(), None);
        assert_eq!(PairedSuccess::default().kappa(), None);
    }

    #[test]
    fn reads_back_and_refuses_an_unknown_field() {
        let c = PairedSuccess { both: 4, imagined_only: 3, sim_only: 2, neither: 1 };
        let json = serde_json::to_value(c).unwrap();
        assert_eq!(json, serde_json::json!({"both": 4, "imagined_only": 3, "sim_only": 2, "neither": 1}));
        assert_eq!(serde_json::from_value::<PairedSuccess>(json).unwrap(), c);
        let bad = serde_json::json!({"both": 4, "imagined_only": 3, "sim_only": 2, "neither": 1, "al": 0});
        assert!(serde_json::from_value::<PairedSuccess>(bad).is_err());
    }
}
