//! What a report shows, read from `rank`'s `results.json`: per-policy scores
//! of both branches with their CIs, and the agreement metrics with theirs.
//! Plain data, so that the plots, tables and HTML never touch JSON paths.

use serde_json::Value;

/// An estimate with an optional 95% interval.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Est {
    /// Point estimate.
    pub value: f64,
    /// 95% interval.
    pub ci: Option<[f64; 2]>,
}

impl Est {
    fn from(v: &Value, ci: &Value) -> Option<Self> {
        Some(Self { value: v.as_f64()?, ci: pair(ci) })
    }

    /// `0.812 [0.78, 0.84]`.
    pub fn fmt(&self, digits: usize) -> String {
        match self.ci {
            Some([a, b]) => format!("{:.d$} [{:.d$}, {:.d$}]", self.value, a, b, d = digits),
            None => format!("{:.d$}", self.value, d = digits),
        }
    }
}

fn pair(v: &Value) -> Option<[f64; 2]> {
    let a = v.as_array()?;
    Some([a.first()?.as_f64()?, a.get(1)?.as_f64()?])
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
    fn from(v: &Value) -> Option<Self> {
        Some(Self {
            mean: Est::from(&v["mean"], &v["ci95"])?,
            success: Est::from(&v["success_rate"], &v["success_ci95"])?,
        })
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
    /// Scenario name.
    pub scenario: String,
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
    /// Reads a parsed `results.json`; `None` names nothing, so callers say which file.
    pub fn from_results(r: &Value) -> Option<Self> {
        let policies = r["policies"]
            .as_array()?
            .iter()
            .map(|p| {
                Some(PolicyScores {
                    name: p["name"].as_str()?.to_string(),
                    sim: BranchScores::from(&p["sim"])?,
                    world_model: BranchScores::from(&p["world_model"])?,
                    episodes: p["sim"]["episodes"].as_u64().unwrap_or(0),
                })
            })
            .collect::<Option<Vec<_>>>()?;
        let ag = &r["agreement"];
        let est = |k: &str| Est::from(&ag[k], &ag["ci95"][k]);
        Some(Self {
            policies,
            pearson: est("pearson"),
            spearman: est("spearman"),
            kendall: est("kendall_tau_b"),
            inversions: est("rank_inversions"),
            mmrv: est("mmrv"),
            regret: est("regret_at_1"),
            scenario: r["scenario"].as_str().unwrap_or("?").to_string(),
            world_model: r["world_model"].as_str().unwrap_or("?").to_string(),
            episodes: r["episodes"].as_u64().unwrap_or(0),
            seed_start: r["seed_start"].as_u64().unwrap_or(0),
            failed: r["failed_policies"]
                .as_array()
                .into_iter()
                .flatten()
                .map(|f| {
                    (
                        f["policy"].as_str().unwrap_or("?").to_string(),
                        f["error"].as_str().unwrap_or("").to_string(),
                    )
                })
                .collect(),
        })
    }

    /// The agreement metrics as (label, estimate, decimals) for tables and captions;
    /// rank inversions are a count, shown (with their CI) as whole numbers.
    pub fn metrics(&self) -> Vec<(&'static str, Option<Est>, usize)> {
        vec![
            ("Pearson r", self.pearson, 3),
            ("Spearman ρ", self.spearman, 3),
            ("Kendall τ_b", self.kendall, 3),
            ("Rank inversions", self.inversions, 0),
            ("MMRV", self.mmrv, 3),
            ("Regret@1", self.regret, 3),
        ]
    }
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
                          "ci95": {"mmrv": [0.0, 0.1]}},
            "failed_policies": [{"policy": "c", "error": "bad"}],
        });
        let s = Summary::from_results(&r).unwrap();
        assert_eq!(s.policies[0].sim.mean.fmt(2), "0.50 [0.40, 0.60]");
        assert_eq!(s.policies[0].world_model.mean.fmt(2), "0.40");
        assert_eq!(s.pearson, None);
        assert_eq!(s.mmrv.unwrap().ci, Some([0.0, 0.1]));
        assert_eq!(s.failed, vec![("c".to_string(), "bad".to_string())]);
    }
}
