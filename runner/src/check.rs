//! What `report` accepts from a `results.json`: besides its types (checked by
//! `RankResults::read`, naming the field), every number the report shows must be one a
//! run can produce. A hand-edited or damaged file with Pearson 5 or a success rate of
//! −3 is refused, naming the field, rather than drawn as if it were a result.

use harness::results::{BranchStats, RankResults};

use crate::error::RunError;

/// Checks the ranges of every shown number of `r`.
///
/// # Errors
/// [`RunError::OutOfRange`]: the first value out of range, named by its path in the
/// file, and how many more there are.
pub fn ranges(r: &RankResults) -> Result<(), RunError> {
    let mut bad: Vec<String> = Vec::new();
    let mut unit = |field: String, v: f64| {
        if !(v.is_finite() && (0.0..=1.0).contains(&v)) {
            bad.push(format!("{field} = {v} (must be in [0, 1])"));
        }
    };
    for (i, p) in r.policies.iter().enumerate() {
        for (b, s) in [("sim", &p.sim), ("world_model", &p.world_model)] {
            let at = format!("policies[{i}].{b}");
            branch(&at, s, &mut unit);
        }
    }
    let a = &r.agreement;
    let mut corr = |field: &str, v: Option<f64>| {
        if let Some(v) = v.filter(|v| !(v.is_finite() && (-1.0..=1.0).contains(v))) {
            bad.push(format!("agreement.{field} = {v} (must be in [-1, 1])"));
        }
    };
    corr("pearson", a.pearson);
    corr("spearman", a.spearman);
    corr("kendall_tau_b", a.kendall_tau_b);
    for (field, v) in [("mmrv", a.mmrv), ("regret_at_1", a.regret_at_1), ("mean_abs_error", a.mean_abs_error)]
    {
        if let Some(v) = v.filter(|v| !(v.is_finite() && (0.0..=1.0).contains(v))) {
            bad.push(format!("agreement.{field} = {v} (must be in [0, 1])"));
        }
    }
    if let Some(n) = a.rank_inversions {
        let k = r.policies.len();
        if n > k * k.saturating_sub(1) / 2 {
            bad.push(format!(
                "agreement.rank_inversions = {n} (at most {} pairs of {k} policies)",
                k * k.saturating_sub(1) / 2
            ));
        }
    }
    match bad.first() {
        Some(first) => Err(RunError::OutOfRange { first: first.clone(), more: bad.len() - 1 }),
        None => Ok(()),
    }
}

/// The checks of one branch's statistics under `at`.
fn branch(at: &str, s: &BranchStats, unit: &mut impl FnMut(String, f64)) {
    unit(format!("{at}.mean"), s.mean);
    unit(format!("{at}.success_rate"), s.success_rate);
    for (k, v) in s.success_ci95.iter().enumerate() {
        unit(format!("{at}.success_ci95[{k}]"), *v);
    }
    for (k, v) in s.ci95.iter().flatten().enumerate() {
        unit(format!("{at}.ci95[{k}]"), *v);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn impossible_values_are_named() {
        // At 92f9f2b `report` drew a results.json with Pearson 5 and a success rate of -3.
        use harness::results::{Branch, EpisodeRow, RunTiming};
        let mut rows = Vec::new();
        for (p, score) in [("a", 0.2), ("b", 0.6), ("c", 0.9)] {
            for seed in 0..4 {
                for b in [Branch::Sim, Branch::WorldModel] {
                    rows.push(EpisodeRow::new(p, seed, b, score, score, score, 0.95, 10));
                }
            }
        }
        let names: Vec<String> = ["a", "b", "c"].map(String::from).to_vec();
        let (policies, agreement) = harness::summarise::summarise(&rows, &names, 20, 0);
        let timing = RunTiming {
            wall_seconds: 1.0,
            sim_seconds: 0.0,
            world_model_seconds: 0.0,
            world_model_ms_per_frame: 0.0,
            policy_seconds: 0.0,
            note: String::new(),
        };
        let ok = RankResults {
            schema_version: harness::results::RESULTS_SCHEMA,
            scenario: "pusht".into(),
            world_model: "wm".into(),
            episodes: 4,
            seed_start: 0,
            max_steps: 10,
            scoring: None,
            simulator: None,
            policies,
            agreement,
            failed_policies: Vec::new(),
            timing,
        };
        ranges(&ok).unwrap();
        let mut r = ok.clone();
        r.agreement.pearson = Some(5.0);
        assert!(ranges(&r).unwrap_err().to_string().contains("agreement.pearson = 5"));
        let mut r = ok.clone();
        r.policies[1].sim.success_rate = -3.0;
        assert!(ranges(&r).unwrap_err().to_string().contains("policies[1].sim.success_rate = -3"));
    }
}
