//! `plan`'s `results.json`, typed: per planner the mean score (bootstrap CI), the
//! success rate (Wilson CI) and the paired difference from `none` on the same seeds
//! (bootstrap CI of the mean difference); for the world-model planner, its agreement
//! with the simulator's picks and its regret; then the run's settings and timing.
//!
//! Each struct declares its fields in alphabetical order: serde writes them in
//! declaration order, and the file was written with sorted keys before it was typed, so
//! a run writes the same bytes as before.

use std::collections::BTreeMap;

use harness::metrics::bootstrap::{mean_ci, wilson};
use serde::{Deserialize, Serialize};

use super::{PlanRow, Planner};
use crate::start::Timing;

/// What the world-model planner's picks were worth, judged by the simulator.
pub const VS_SIMULATOR_NOTE: &str = "at every decision the simulator also scored the same proposals from \
    the true state: how often both picked the same one (chance is 1 / proposals), and how much farther \
    from the goal (mean block-pixel distance, world units) the world model's pick ends than the \
    simulator's best, against a pick at random";

/// A planner's paired difference from `none` on the same seeds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VsNone {
    /// Bootstrap 95% CI of the mean difference (`None` with fewer than two seeds).
    pub ci95: Option<[f64; 2]>,
    /// Seeds where this planner scored higher than `none`.
    pub episodes_better: usize,
    /// Seeds where it scored lower.
    pub episodes_worse: usize,
    /// Mean of (this planner's score − `none`'s) over the seeds.
    pub mean_difference: f64,
}

/// The world-model planner's picks against the simulator's on the same proposals.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VsSimulator {
    /// Mean over decisions of the cost's excess of the world model's pick over the best.
    pub mean_regret_units: f64,
    /// What these numbers mean ([`VS_SIMULATOR_NOTE`]).
    pub note: String,
    /// Fraction of decisions where both picked the same proposal.
    pub pick_agreement: f64,
    /// The same regret for a pick at random: the chance level.
    pub random_pick_mean_regret_units: f64,
}

/// One planner's statistics over its episodes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlannerStats {
    /// Bootstrap 95% CI of the mean score.
    pub ci95: Option<[f64; 2]>,
    /// Decisions taken over all episodes.
    pub decisions: usize,
    /// Episodes.
    pub episodes: usize,
    /// Mean score.
    pub mean: f64,
    /// Mean control steps per episode.
    pub mean_steps: f64,
    /// Fraction of decisions that executed another proposal than the first.
    pub replaced_fraction: f64,
    /// Wilson 95% CI of the success rate.
    pub success_ci95: [f64; 2],
    /// Fraction of episodes that succeeded.
    pub success_rate: f64,
    /// Against `none` on the same seeds (absent for `none`, or without matching seeds).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vs_none: Option<VsNone>,
    /// The world-model planner's picks against the simulator's (absent for the others).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vs_simulator: Option<VsSimulator>,
}

/// Where a `plan` run's time went.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanTiming {
    /// Policy inference.
    pub policy_seconds: f64,
    /// Simulator stepping and rendering.
    pub sim_seconds: f64,
    /// The whole run, this process.
    pub wall_seconds: f64,
    /// World-model time per generated frame.
    pub world_model_ms_per_frame: f64,
    /// World-model prediction and decoding.
    pub world_model_seconds: f64,
}

impl PlanTiming {
    /// The timing of `wall_seconds` of a run whose parts took `t`.
    pub fn new(wall_seconds: f64, t: &Timing) -> Self {
        Self {
            policy_seconds: t.policy_s,
            sim_seconds: t.sim_s,
            wall_seconds,
            world_model_ms_per_frame: 1e3 * t.world_model_s / t.frames.max(1) as f64,
            world_model_seconds: t.world_model_s,
        }
    }
}

/// The run's settings that `results.json` repeats beside its statistics.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanSettings {
    /// The proposing policy's name.
    pub policy: String,
    /// Proposals per decision.
    pub proposals: usize,
    /// Actions imagined per proposal.
    pub imagine: usize,
    /// Actions executed per decision.
    pub execute: usize,
    /// Episodes per planner.
    pub episodes: usize,
    /// The first episode seed.
    pub seed_start: u64,
}

/// A `plan` run's `results.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanResults {
    /// Episodes per planner.
    pub episodes: usize,
    /// Actions executed per decision.
    pub execute: usize,
    /// Actions imagined per proposal.
    pub imagine: usize,
    /// Each planner's statistics, by name.
    pub planners: BTreeMap<String, PlannerStats>,
    /// The proposing policy's name.
    pub policy: String,
    /// Proposals per decision.
    pub proposals: usize,
    /// The first episode seed.
    pub seed_start: u64,
    /// Where the time went.
    pub timing: PlanTiming,
}

/// `planner`'s rows in seed order.
fn sorted(rows: &[PlanRow], planner: Planner) -> Vec<&PlanRow> {
    let mut v: Vec<&PlanRow> = rows.iter().filter(|r| r.planner == planner.name()).collect();
    v.sort_by_key(|r| r.seed);
    v
}

/// The mean of `values` (0 for none).
fn mean(values: impl Iterator<Item = f64>, n: usize) -> f64 {
    values.sum::<f64>() / n.max(1) as f64
}

/// One planner's statistics; `base` is `none`'s rows in seed order.
fn planner_stats(
    rs: &[&PlanRow],
    base: &[&PlanRow],
    p: Planner,
    bootstrap: usize,
    seed: u64,
) -> PlannerStats {
    let scores: Vec<f64> = rs.iter().map(|r| r.score).collect();
    let n = scores.len();
    let k = rs.iter().filter(|r| r.success).count();
    let (lo, hi) = wilson(k, n, 1.96);
    let decisions: usize = rs.iter().map(|r| r.decisions).sum();
    let paired = p != Planner::None && base.len() == n && base.iter().zip(rs).all(|(b, r)| b.seed == r.seed);
    let vs_none = paired.then(|| {
        let diff: Vec<f64> = rs.iter().zip(base).map(|(r, b)| r.score - b.score).collect();
        VsNone {
            ci95: mean_ci(&diff, bootstrap, seed ^ 0x706c_616e),
            episodes_better: diff.iter().filter(|d| **d > 1e-12).count(),
            episodes_worse: diff.iter().filter(|d| **d < -1e-12).count(),
            mean_difference: mean(diff.iter().copied(), n),
        }
    });
    let vs_simulator = (p == Planner::WorldModel).then(|| {
        let per_decision = |v: f64| v / decisions.max(1) as f64;
        VsSimulator {
            mean_regret_units: per_decision(rs.iter().filter_map(|r| r.regret).sum()),
            note: VS_SIMULATOR_NOTE.to_string(),
            pick_agreement: per_decision(rs.iter().filter_map(|r| r.agreed).sum::<usize>() as f64),
            random_pick_mean_regret_units: per_decision(rs.iter().filter_map(|r| r.regret_random).sum()),
        }
    });
    PlannerStats {
        ci95: mean_ci(&scores, bootstrap, seed),
        decisions,
        episodes: n,
        mean: mean(scores.iter().copied(), n),
        mean_steps: mean(rs.iter().map(|r| r.steps as f64), n),
        replaced_fraction: rs.iter().map(|r| r.replaced).sum::<usize>() as f64 / decisions.max(1) as f64,
        success_ci95: [lo, hi],
        success_rate: k as f64 / n.max(1) as f64,
        vs_none,
        vs_simulator,
    }
}

/// `results.json` of a `plan` run: each planner's statistics over `rows`, bootstrap CIs
/// of `bootstrap` replicates drawn from `seed`.
pub fn summarise(
    rows: &[PlanRow],
    planners: &[Planner],
    bootstrap: usize,
    seed: u64,
    settings: PlanSettings,
    timing: PlanTiming,
) -> PlanResults {
    let base = sorted(rows, Planner::None);
    let planners = planners
        .iter()
        .map(|&p| (p.name().to_string(), planner_stats(&sorted(rows, p), &base, p, bootstrap, seed)))
        .collect();
    let PlanSettings { policy, proposals, imagine, execute, episodes, seed_start } = settings;
    PlanResults { episodes, execute, imagine, planners, policy, proposals, seed_start, timing }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(planner: Planner, seed: u64, score: f64, agreed: Option<usize>) -> PlanRow {
        PlanRow {
            planner: planner.name().to_string(),
            seed,
            score,
            max_coverage: score,
            final_coverage: score,
            success: score > 0.9,
            steps: 10,
            decisions: 2,
            replaced: 1,
            agreed,
            regret: agreed.map(|_| 3.0),
            regret_random: agreed.map(|_| 5.0),
        }
    }

    fn settings() -> PlanSettings {
        PlanSettings { policy: "p".into(), proposals: 4, imagine: 8, execute: 8, episodes: 2, seed_start: 7 }
    }

    /// Two seeds, `none` scoring 0.5 and 1.0, the world model 0.75 and 1.0: its mean
    /// difference is (0.25 + 0) / 2 = 0.125, one seed better, none worse; it agreed on
    /// 1 + 2 of 4 decisions (0.75), regret (3 + 3) / 4 = 1.5, at random (5 + 5) / 4 = 2.5.
    #[test]
    fn statistics_by_hand() {
        let rows = [
            row(Planner::None, 8, 1.0, None),
            row(Planner::None, 7, 0.5, None),
            row(Planner::WorldModel, 7, 0.75, Some(1)),
            row(Planner::WorldModel, 8, 1.0, Some(2)),
        ];
        let timing =
            PlanTiming::new(10.0, &Timing { sim_s: 1.0, world_model_s: 2.0, policy_s: 3.0, frames: 4 });
        let res = summarise(&rows, &[Planner::None, Planner::WorldModel], 100, 0, settings(), timing);
        let none = &res.planners["none"];
        assert_eq!((none.episodes, none.mean, none.success_rate), (2, 0.75, 0.5));
        assert!(none.vs_none.is_none() && none.vs_simulator.is_none());
        let wm = &res.planners["world-model"];
        let d = wm.vs_none.as_ref().expect("paired with none");
        assert_eq!((d.mean_difference, d.episodes_better, d.episodes_worse), (0.125, 1, 0));
        let s = wm.vs_simulator.as_ref().expect("the world model's picks");
        assert_eq!(
            (s.pick_agreement, s.mean_regret_units, s.random_pick_mean_regret_units),
            (0.75, 1.5, 2.5)
        );
        assert_eq!((wm.replaced_fraction, wm.mean_steps), (0.5, 10.0));
        // 2 s of world model over 4 frames: 500 ms a frame.
        assert_eq!(res.timing.world_model_ms_per_frame, 500.0);
    }

    /// The file's keys come out sorted, as they did when the file was a JSON map, and it
    /// reads back as written.
    #[test]
    fn keys_sorted_and_round_trip() {
        let rows = [row(Planner::None, 7, 0.5, None), row(Planner::WorldModel, 7, 1.0, Some(1))];
        let timing = PlanTiming::new(1.0, &Timing::default());
        let res = summarise(&rows, &[Planner::None, Planner::WorldModel], 10, 0, settings(), timing);
        let text = serde_json::to_string(&res).expect("serialises");
        let value: serde_json::Value = serde_json::from_str(&text).expect("parses");
        assert_eq!(serde_json::to_string(&value).expect("serialises"), text, "keys out of order");
        assert_eq!(serde_json::from_str::<PlanResults>(&text).expect("reads back"), res);
    }
}
