//! The statistics of a ranking run, from its rows: per policy and branch the mean
//! score with a bootstrap CI, the success rate with a Wilson CI, the steps to
//! success and the scene
//! checks; across policies, how well the world model's ranking agrees with the
//! simulator's (with bootstrap CIs). Rows may come in any order (a resumed,
//! sharded or multi-threaded run gives the same results as one uninterrupted run).

use std::collections::BTreeMap;

use crate::metrics::agreement;
use crate::metrics::bootstrap::{agreement_ci, mean_ci, wilson};
use crate::metrics::ceiling::noise_ceiling;
use crate::results::{AgreementSummary, Branch, BranchStats, EpisodeRow, Named, PairedSuccess, PolicyResult};

/// Mean, bootstrap CI, success rate and Wilson CI of one branch of one policy.
pub fn branch_stats(rows: &[&EpisodeRow], bootstrap: usize, seed: u64) -> BranchStats {
    let scores: Vec<f64> = rows.iter().map(|r| r.score).collect();
    let n = scores.len();
    let k = rows.iter().filter(|r| r.success).count();
    let mean_of = |v: Vec<f64>| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
    let (lo, hi) = wilson(k, n, 1.959_963_984_540_054);
    BranchStats {
        mean: scores.iter().sum::<f64>() / n.max(1) as f64,
        ci95: mean_ci(&scores, bootstrap, seed),
        success_rate: k as f64 / n.max(1) as f64,
        success_ci95: [lo, hi],
        steps_to_success: mean_of(rows.iter().filter(|r| r.success).map(|r| r.steps as f64).collect()),
        episodes: n,
        scene: scene_means(rows),
    }
}

/// The mean of each scene check over the rows that made it.
fn scene_means(rows: &[&EpisodeRow]) -> Named {
    let mut sums: BTreeMap<&str, (f64, usize)> = BTreeMap::new();
    for (k, v) in rows.iter().flat_map(|r| &r.scene) {
        let e = sums.entry(k.as_str()).or_default();
        (e.0, e.1) = (e.0 + v, e.1 + 1);
    }
    sums.into_iter().map(|(k, (sum, n))| (k.to_string(), sum / n as f64)).collect()
}

/// Per-policy statistics and agreement, from rows (any order; sorted here).
/// `policies` fixes the output order; policies without complete pairs are skipped.
pub fn summarise(
    rows: &[EpisodeRow],
    policies: &[String],
    bootstrap: usize,
    seed: u64,
) -> (Vec<PolicyResult>, AgreementSummary) {
    let mut by: BTreeMap<(&str, u64), [Option<&EpisodeRow>; 2]> = BTreeMap::new();
    for r in rows {
        let e = by.entry((r.policy.as_str(), r.seed)).or_default();
        e[usize::from(r.branch == Branch::WorldModel)] = Some(r);
    }
    let mut out = Vec::new();
    let mut pairs: Vec<(Vec<f64>, Vec<f64>)> = Vec::new();
    let mut names = Vec::new();
    for p in policies {
        let eps: Vec<[&EpisodeRow; 2]> = by
            .range((p.as_str(), 0)..=(p.as_str(), u64::MAX))
            .filter_map(|(_, v)| Some([v[0]?, v[1]?]))
            .collect();
        if eps.is_empty() {
            continue;
        }
        let sim: Vec<&EpisodeRow> = eps.iter().map(|e| e[0]).collect();
        let wm: Vec<&EpisodeRow> = eps.iter().map(|e| e[1]).collect();
        let errs: Vec<f64> = sim.iter().filter_map(|r| r.scorer_abs_error).collect();
        out.push(PolicyResult {
            name: p.clone(),
            sim: branch_stats(&sim, bootstrap, seed),
            world_model: branch_stats(&wm, bootstrap, seed),
            frame_scorer_mean_abs_error: errs.iter().sum::<f64>() / errs.len().max(1) as f64,
            paired_success: Some(PairedSuccess::count(eps.iter().map(|e| (e[0].success, e[1].success)))),
        });
        pairs.push((wm.iter().map(|r| r.score).collect(), sim.iter().map(|r| r.score).collect()));
        names.push(p.as_str());
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let pred: Vec<f64> = pairs.iter().map(|(w, _)| mean(w)).collect();
    let act: Vec<f64> = pairs.iter().map(|(_, s)| mean(s)).collect();
    let m = agreement(&pred, &act);
    let ci = (pairs.len() >= 2 && pairs.iter().all(|(w, _)| w.len() >= 2))
        .then(|| agreement_ci(&pairs, bootstrap, seed));
    let mut summary = m.summary(&names, ci.as_ref());
    let sims: Vec<Vec<f64>> = pairs.into_iter().map(|(_, s)| s).collect();
    summary.noise_ceiling = noise_ceiling(&sims, bootstrap, seed);
    (out, summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(p: &str, seed: u64, b: Branch, score: f64) -> EpisodeRow {
        EpisodeRow::new(p, seed, b, score, score * 0.95, 0.0, 0.95, 10)
    }

    #[test]
    fn summary_pairs_branches_and_computes_agreement() {
        // Policy a: sim (0.2, 0.4) mean 0.3, wm (0.1, 0.3) mean 0.2;
        // policy b: sim (0.8, 1.0) mean 0.9, wm (0.7, 0.9) mean 0.8. Same order: r = 1, no inversion.
        let rows = vec![
            row("b", 2, Branch::WorldModel, 0.9),
            row("a", 1, Branch::Sim, 0.2),
            row("a", 1, Branch::WorldModel, 0.1),
            row("a", 2, Branch::Sim, 0.4),
            row("a", 2, Branch::WorldModel, 0.3),
            row("b", 1, Branch::Sim, 0.8),
            row("b", 1, Branch::WorldModel, 0.7),
            row("b", 2, Branch::Sim, 1.0),
            row("a", 3, Branch::Sim, 0.9), // unpaired: ignored
        ];
        let s = summarise(&rows, &["a".into(), "b".into()], 200, 0);
        assert!((s.0[0].sim.mean - 0.3).abs() < 1e-12);
        assert!((s.0[1].world_model.mean - 0.8).abs() < 1e-12);
        // Success: max coverage = 0.95 score > 0.95 only for score 1.0 (0.95 > 0.95 is false): none.
        assert_eq!(s.0[1].sim.success_rate, 0.0);
        assert!((s.1.pearson.unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(s.1.rank_inversions, Some(0));
        // No scene checks recorded (a task without them): none.
        assert!(s.0[0].sim.scene.is_empty());
        // Same input in another order gives the same summary.
        let mut rev = rows.clone();
        rev.reverse();
        assert_eq!(summarise(&rev, &["a".into(), "b".into()], 200, 0), s);
        // No episode succeeded: no steps to success.
        assert_eq!(s.0[0].sim.steps_to_success, None);
        // The noise ceiling resamples the MuJoCo episodes: a (0.2, 0.4) and b (0.8, 1.0)
        // never overlap (a's means lie in [0.2, 0.4], b's in [0.8, 1.0]), so two
        // resampled runs always order them alike: no inversion.
        let ceiling = s.1.noise_ceiling.as_ref().unwrap();
        assert_eq!((ceiling.rank_inversions, ceiling.replicates), (0.0, 200));
    }

    #[test]
    fn scene_checks_are_averaged_by_name_over_the_rows_that_made_them() {
        // Three MuJoCo rows of one policy: block_area 0.5 and 1.0 (the third row made no
        // checks), goal_kept 0.25 on the first only: means 0.75 and 0.25.
        let check = |b: f64, g: Option<f64>| {
            let mut c = vec![("block_area", b)];
            c.extend(g.map(|g| ("goal_kept", g)));
            crate::judge::SceneCheck(c)
        };
        let rows = [
            row("a", 1, Branch::Sim, 0.1).with_scene(Some(&check(0.5, Some(0.25)))),
            row("a", 2, Branch::Sim, 0.2).with_scene(Some(&check(1.0, None))),
            row("a", 3, Branch::Sim, 0.3),
        ];
        let s = branch_stats(&rows.iter().collect::<Vec<_>>(), 10, 0);
        let want: Named = [("block_area".to_string(), 0.75), ("goal_kept".to_string(), 0.25)].into();
        assert_eq!(s.scene, want);
    }

    #[test]
    fn paired_success_counts_each_seed_in_both_branches() {
        // Success at 0.5. Seeds 1–5, (MuJoCo, imagined) success: 1 (T, T), 2 (F, T),
        // 3 (F, T), 4 (T, F), 5 (F, F); seed 6 has no imagined episode and is left out.
        // So both 1, imagined only 2, MuJoCo only 1, neither 1; agreement (1 + 1) / 5 = 0.4.
        let ep = |seed, b, s: f64| EpisodeRow::new("a", seed, b, s, s, s, 0.5, 10);
        let (sim, wm) = (Branch::Sim, Branch::WorldModel);
        let rows = vec![
            ep(1, sim, 1.0),
            ep(1, wm, 1.0),
            ep(2, sim, 0.0),
            ep(2, wm, 1.0),
            ep(3, wm, 1.0),
            ep(3, sim, 0.0),
            ep(4, sim, 1.0),
            ep(4, wm, 0.0),
            ep(5, sim, 0.0),
            ep(5, wm, 0.0),
            ep(6, sim, 1.0),
        ];
        let (p, _) = summarise(&rows, &["a".into()], 10, 0);
        let c = p[0].paired_success.unwrap();
        assert_eq!(c, PairedSuccess { both: 1, imagined_only: 2, sim_only: 1, neither: 1 });
        assert!((c.agreement() - 0.4).abs() < 1e-12);
        // The success rates alone: MuJoCo 2/5 = 0.4, imagined 3/5 = 0.6.
        assert!((p[0].sim.success_rate - 0.4).abs() < 1e-12);
        assert!((p[0].world_model.success_rate - 0.6).abs() < 1e-12);
    }

    #[test]
    fn steps_to_success_average_the_successful_episodes_only() {
        // Success at 0.5: two successes after 16 and 40 steps, one failure that ran 400.
        let rows = [
            EpisodeRow::new("a", 1, Branch::Sim, 1.0, 1.0, 1.0, 0.5, 16),
            EpisodeRow::new("a", 2, Branch::Sim, 1.0, 1.0, 1.0, 0.5, 40),
            EpisodeRow::new("a", 3, Branch::Sim, 0.0, 0.0, 0.0, 0.5, 400),
        ];
        let refs: Vec<&EpisodeRow> = rows.iter().collect();
        let b = branch_stats(&refs, 10, 0);
        // (16 + 40) / 2 = 28; success rate 2/3.
        assert_eq!(b.steps_to_success, Some(28.0));
        assert!((b.success_rate - 2.0 / 3.0).abs() < 1e-12);
    }
}
