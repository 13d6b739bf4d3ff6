//! What a report shows, read from `rank`'s `results.json`: per-policy scores
//! of both branches with their CIs, and the agreement metrics with theirs.
//! Plain data, so that the plots, tables and HTML never touch JSON paths.

use harness::metrics::bootstrap::AgreementCi;
use harness::metrics::ceiling::NoiseCeiling;
use harness::results::{BranchStats, PairedSuccess, RankResults};

/// An estimate with an optional 95% interval.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Est {
    /// Point estimate.
    pub value: f64,
    /// 95% interval.
    pub ci: Option<[f64; 2]>,
}

impl Est {
    fn new(value: f64, ci: Option<[f64; 2]>) -> Self {
        Self { value, ci }
    }

    /// The square of a correlation estimate (Pearson r → r²): the point squared, and the
    /// interval's image under x ↦ x² (from 0 when the interval spans 0).
    pub fn squared(self) -> Self {
        let ci = self.ci.map(|[a, b]| {
            let (lo, hi) = (a.abs().min(b.abs()), a.abs().max(b.abs()));
            [if a <= 0.0 && b >= 0.0 { 0.0 } else { lo * lo }, hi * hi]
        });
        Self { value: self.value * self.value, ci }
    }

    /// `0.812 [0.78, 0.84]`.
    pub fn fmt(&self, digits: usize) -> String {
        match self.ci {
            Some([a, b]) => format!("{:.d$} [{:.d$}, {:.d$}]", self.value, a, b, d = digits),
            None => format!("{:.d$}", self.value, d = digits),
        }
    }
}

/// One branch of one policy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BranchScores {
    /// Mean score with a bootstrap CI.
    pub mean: Est,
    /// Success rate with a Wilson CI.
    pub success: Est,
}

impl BranchScores {
    fn from(b: &BranchStats) -> Self {
        Self { mean: Est::new(b.mean, b.ci95), success: Est::new(b.success_rate, Some(b.success_ci95)) }
    }
}

/// One policy's row.
#[derive(Clone, Debug, PartialEq)]
pub struct PolicyScores {
    /// Checkpoint name.
    pub name: String,
    /// MuJoCo branch.
    pub sim: BranchScores,
    /// World-model branch.
    pub world_model: BranchScores,
    /// Episodes per branch.
    pub episodes: u64,
    /// Seeds counted by success in both branches (none in results written before it).
    pub paired: Option<PairedSuccess>,
}

/// Everything the report shows.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// Policies in run order.
    pub policies: Vec<PolicyScores>,
    /// Pearson r.
    pub pearson: Option<Est>,
    /// Spearman ρ.
    pub spearman: Option<Est>,
    /// Kendall τ_b.
    pub kendall: Option<Est>,
    /// Rank inversions (count).
    pub inversions: Option<Est>,
    /// MMRV.
    pub mmrv: Option<Est>,
    /// Regret@1.
    pub regret: Option<Est>,
    /// Mean absolute error of the imagined scores against MuJoCo's, over policies.
    pub mae: Option<f64>,
    /// How well two resampled MuJoCo runs of this size agree (none in older results).
    pub ceiling: Option<NoiseCeiling>,
    /// Scenario name.
    pub scenario: String,
    /// The reference simulator's name ("MuJoCo" for Push-T, Lift and Can).
    pub simulator: String,
    /// World-model folder.
    pub world_model: String,
    /// Episodes per policy.
    pub episodes: u64,
    /// First seed.
    pub seed_start: u64,
    /// Policies that failed, with their errors.
    pub failed: Vec<(String, String)>,
}

impl Summary {
    /// What the report shows of a run's results.
    pub fn from_results(r: &RankResults) -> Self {
        let ag = &r.agreement;
        let ci = |pick: fn(&AgreementCi) -> Option<[f64; 2]>| ag.ci95.as_ref().and_then(pick);
        let est = |v: Option<f64>, c: Option<[f64; 2]>| v.map(|v| Est::new(v, c));
        Self {
            policies: r
                .policies
                .iter()
                .map(|p| PolicyScores {
                    name: p.name.clone(),
                    sim: BranchScores::from(&p.sim),
                    world_model: BranchScores::from(&p.world_model),
                    episodes: p.sim.episodes as u64,
                    paired: p.paired_success,
                })
                .collect(),
            pearson: est(ag.pearson, ci(|c| c.pearson)),
            spearman: est(ag.spearman, ci(|c| c.spearman)),
            kendall: est(ag.kendall_tau_b, ci(|c| c.kendall_tau_b)),
            inversions: est(ag.rank_inversions.map(|k| k as f64), ci(|c| c.rank_inversions)),
            mmrv: est(ag.mmrv, ci(|c| c.mmrv)),
            regret: est(ag.regret_at_1, ci(|c| c.regret_at_1)),
            mae: ag.mean_abs_error,
            ceiling: ag.noise_ceiling.clone(),
            scenario: r.scenario.clone(),
            simulator: r.simulator().to_string(),
            world_model: r.world_model.display().to_string(),
            episodes: r.episodes as u64,
            seed_start: r.seed_start,
            failed: r.failed_policies.iter().map(|f| (f.policy.clone(), f.error.clone())).collect(),
        }
    }

    /// The agreement metrics as (label, estimate, decimals) for tables and captions;
    /// rank inversions are a count, shown (with their CI) as whole numbers.
    pub fn metrics(&self) -> Vec<(&'static str, Option<Est>, usize)> {
        vec![
            ("Pearson r", self.pearson, 3),
            ("Pearson r²", self.pearson.map(Est::squared), 3),
            ("Spearman ρ", self.spearman, 3),
            ("Kendall τ_b", self.kendall, 3),
            ("Rank inversions", self.inversions, 0),
            ("MMRV", self.mmrv, 3),
            ("Regret@1", self.regret, 3),
        ]
    }
}

/// Test fixtures: a `results.json` given in part (policies, agreement and a few
/// top-level fields), completed with neutral values, as the typed results.
#[cfg(test)]
mod squared_tests {
    use super::Est;

    #[test]
    fn a_squared_interval_starts_at_zero_when_it_spans_zero() {
        // 0.9² = 0.81 with [0.8, 0.95] → [0.64, 0.9025]; r = 0.5 in [−0.6, 0.9] → [0, 0.81];
        // r = −0.7 in [−0.9, −0.2] → 0.49 in [0.04, 0.81].
        let sq = |v: f64, a: f64, b: f64| Est::new(v, Some([a, b])).squared();
        let near = |e: Est, v: f64, a: f64, b: f64| {
            let c = e.ci.unwrap_or([f64::NAN; 2]);
            (e.value - v).abs() < 1e-12 && (c[0] - a).abs() < 1e-12 && (c[1] - b).abs() < 1e-12
        };
        assert!(near(sq(0.9, 0.8, 0.95), 0.81, 0.64, 0.9025));
        assert!(near(sq(0.5, -0.6, 0.9), 0.25, 0.0, 0.81));
        assert!(near(sq(-0.7, -0.9, -0.2), 0.49, 0.04, 0.81));
    }
}

#[cfg(test)]
pub(crate) fn fixture(partial: serde_json::Value) -> RankResults {
    let mut v = serde_json::json!({
        "scenario": "pusht", "world_model": "wm", "episodes": 1, "seed_start": 0, "max_steps": 300,
        "policies": [], "failed_policies": [],
        "timing": {"wall_seconds": 0.0, "sim_seconds": 0.0, "world_model_seconds": 0.0,
            "world_model_ms_per_frame": 0.0, "policy_seconds": 0.0, "note": ""},
    });
    for (k, x) in partial.as_object().expect("an object") {
        v[k] = x.clone();
    }
    let metrics = [
        "pearson",
        "spearman",
        "kendall_tau_b",
        "rank_inversions",
        "rank_inversion_fraction",
        "mmrv",
        "regret_at_1",
        "ci95",
    ];
    for k in metrics {
        if v["agreement"].get(k).is_none() {
            v["agreement"][k] = serde_json::Value::Null;
        }
    }
    if v["agreement"]["ci95"].is_object() && v["agreement"]["ci95"].get("replicates").is_none() {
        v["agreement"]["ci95"]["replicates"] = serde_json::json!(0);
    }
    for p in v["policies"].as_array_mut().into_iter().flatten() {
        for b in ["sim", "world_model"] {
            if p[b].get("episodes").is_none() {
                p[b]["episodes"] = serde_json::json!(1);
            }
            if p[b]["success_ci95"].is_null() {
                p[b]["success_ci95"] = serde_json::json!([0.0, 1.0]);
            }
        }
        if p.get("frame_scorer_mean_abs_error").is_none() {
            p["frame_scorer_mean_abs_error"] = serde_json::json!(0.0);
        }
    }
    serde_json::from_value(v).expect("a complete results.json")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_results() {
        let r = serde_json::json!({
            "scenario": "pusht", "world_model": "wm", "episodes": 2, "seed_start": 5,
            "policies": [{"name": "a",
                "sim": {"mean": 0.5, "ci95": [0.4, 0.6], "success_rate": 0.5, "success_ci95": [0.1, 0.9], "episodes": 2},
                "world_model": {"mean": 0.4, "ci95": null, "success_rate": 0.0, "success_ci95": [0.0, 0.6]}}],
            "agreement": {"pearson": null, "rank_inversions": 0, "mmrv": 0.0, "regret_at_1": 0.0,
                          "ci95": {"pearson": null, "spearman": null, "kendall_tau_b": null,
                                   "rank_inversions": null, "mmrv": [0.0, 0.1], "regret_at_1": null, "replicates": 10}},
            "failed_policies": [{"policy": "c", "error": "bad"}],
        });
        let s = Summary::from_results(&fixture(r));
        assert_eq!(s.policies[0].sim.mean.fmt(2), "0.50 [0.40, 0.60]");
        assert_eq!(s.policies[0].world_model.mean.fmt(2), "0.40");
        assert_eq!(s.pearson, None);
        assert_eq!(s.mmrv.unwrap().ci, Some([0.0, 0.1]));
        assert_eq!(s.inversions.unwrap().value, 0.0);
        assert_eq!(s.failed, vec![("c".to_string(), "bad".to_string())]);
    }
}
