//! What a finished `rank` says: the per-policy table and agreement line (through `say`, the
//! binary's stdout), and the exit code of the gates, whose failures go to stderr (its episode
//! tables are `reports::episode_tables`).

use std::path::Path;
use std::process::ExitCode;

use harness::results::RankResults;

/// Exit 1 when a gate fails (or a policy failed, or fewer than two policies were
/// ranked, so no agreement could be measured), 0 otherwise. Undefined metrics fail
/// a gate that asks for them, and are printed as n/a.
pub(crate) fn gates(min_pearson: Option<f64>, max_inversions: Option<u64>, res: &RankResults) -> ExitCode {
    let mut ok = true;
    let ranked = res.policies.len();
    if ranked < 2 {
        eprintln!("only {ranked} policies were ranked: agreement needs at least 2 (its metrics are null)");
        ok = false;
    }
    if let Some(min) = min_pearson {
        match res.agreement.pearson {
            Some(r) if r >= min => {}
            Some(r) => {
                eprintln!("gate failed: Pearson {r:.4} < --min-pearson {min}");
                ok = false;
            }
            None => {
                eprintln!("gate failed: Pearson is undefined (n/a) and --min-pearson {min} needs a value");
                ok = false;
            }
        }
    }
    if let Some(max) = max_inversions {
        match res.agreement.rank_inversions {
            Some(k) if k as u64 <= max => {}
            Some(k) => {
                eprintln!("gate failed: {k} rank inversions > --max-inversions {max}");
                ok = false;
            }
            None => {
                eprintln!(
                    "gate failed: rank inversions are undefined (n/a) and --max-inversions {max} needs a value"
                );
                ok = false;
            }
        }
    }
    if !res.failed_policies.is_empty() {
        eprintln!("{} policies failed (see results.json \"failed_policies\")", res.failed_policies.len());
        ok = false;
    }
    if ok { ExitCode::SUCCESS } else { ExitCode::from(1) }
}

/// The per-policy table, the agreement line and where the results (and the report,
/// when one was written) are (stdout carries results only).
pub(crate) fn print(res: &RankResults, out: &Path, report: Option<&Path>, say: &dyn Fn(&str)) {
    let sim = res.simulator();
    // The task's scene checks by name (Push-T: agent kept, block area, goal kept), the
    // world model's means beside the scores.
    let checks: std::collections::BTreeSet<&str> =
        res.policies.iter().flat_map(|p| p.world_model.scene.keys().map(String::as_str)).collect();
    let scene = !checks.is_empty();
    if scene {
        let names: String = checks.iter().map(|c| format!(" {:>11}", c.replace('_', " "))).collect();
        runner::say!(say, "{:<16} {:>10} {:>12}{names}", "policy", sim, "world model");
    } else {
        // A task without scene checks (robomimic's, scored by success alone): the success
        // rates with their Wilson 95% intervals, the mean steps to success, and the seeds
        // that succeed in one branch only.
        runner::say!(
            say,
            "{:<16} {:>22} {:>22} {:>14} {:>14} {:>14} {:>12} {:>6}",
            "policy",
            format!("{sim} success"),
            "world model success",
            format!("{sim} steps"),
            "wm steps",
            "imagined only",
            format!("{sim} only"),
            "kappa"
        );
    }
    for p in &res.policies {
        let wm = &p.world_model;
        if scene {
            let means: String = checks
                .iter()
                .map(|c| format!(" {:>11.2}", wm.scene.get(*c).copied().unwrap_or(f64::NAN)))
                .collect();
            runner::say!(say, "{:<16} {:>10.3} {:>12.3}{means}", p.name, p.sim.mean, wm.mean);
        } else {
            let rate = |b: &harness::results::BranchStats| {
                format!("{:.2} [{:.2}, {:.2}]", b.success_rate, b.success_ci95[0], b.success_ci95[1])
            };
            let steps = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.1}"));
            let only = |k: fn(&harness::results::PairedSuccess) -> usize| {
                p.paired_success.as_ref().map_or("-".to_string(), |c| k(c).to_string())
            };
            let kappa =
                p.paired_success.and_then(|c| c.kappa()).map_or("-".to_string(), |k| format!("{k:.2}"));
            runner::say!(
                say,
                "{:<16} {:>22} {:>22} {:>14} {:>14} {:>14} {:>12} {:>6}",
                p.name,
                rate(&p.sim),
                rate(wm),
                steps(p.sim.steps_to_success),
                steps(wm.steps_to_success),
                only(|c| c.imagined_only),
                only(|c| c.sim_only),
                kappa
            );
        }
    }
    let ag = &res.agreement;
    let f = |v: Option<f64>| v.map_or("n/a".to_string(), |v| format!("{v:.3}"));
    runner::say!(
        say,
        "Pearson {}  r² {}  Spearman {}  Kendall tau_b {}  inversions {}  MMRV {}  regret@1 {}  MAE {}",
        f(ag.pearson),
        f(ag.pearson_r2),
        f(ag.spearman),
        f(ag.kendall_tau_b),
        ag.rank_inversions.map_or("n/a".to_string(), |k| k.to_string()),
        f(ag.mmrv),
        f(ag.regret_at_1),
        f(ag.mean_abs_error)
    );
    if let Some(c) = &ag.noise_ceiling {
        runner::say!(
            say,
            "noise ceiling (two resampled {sim} runs of this size agree at): Pearson {}  inversions {:.1}  MAE {:.3}",
            c.pearson_text(),
            c.rank_inversions,
            c.mean_abs_error
        );
    }
    runner::say!(say, "results: {}", out.join("results.json").display());
    if let Some(html) = report {
        runner::say!(say, "report: {}", html.display());
    }
}
