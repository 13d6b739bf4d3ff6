//! `plan`'s statistics and files: per planner the mean score (bootstrap CI), the
//! success rate (Wilson CI) and the paired difference from `none` on the same
//! seeds (bootstrap CI of the mean difference); for the world-model planner, its
//! agreement with the simulator's picks and its regret.

use std::path::Path;

use anyhow::{Context, Result};
use harness::metrics::bootstrap::{mean_ci, wilson};
use serde_json::{Value, json};

use engine::plan::{PlanRow, Planner};

fn sorted(rows: &[PlanRow], planner: Planner) -> Vec<&PlanRow> {
    let mut v: Vec<&PlanRow> = rows.iter().filter(|r| r.planner == planner.name()).collect();
    v.sort_by_key(|r| r.seed);
    v
}

/// `results.json`'s `planners` object (and the rest of its statistics).
pub fn summarise(rows: &[PlanRow], planners: &[Planner], bootstrap: usize, seed: u64) -> Value {
    let base = sorted(rows, Planner::None);
    let mut out = serde_json::Map::new();
    for &p in planners {
        let rs = sorted(rows, p);
        let scores: Vec<f64> = rs.iter().map(|r| r.score).collect();
        let n = scores.len();
        let k = rs.iter().filter(|r| r.success).count();
        let (lo, hi) = wilson(k, n, 1.96);
        let decisions: usize = rs.iter().map(|r| r.decisions).sum();
        let mut v = json!({
            "episodes": n,
            "mean": scores.iter().sum::<f64>() / n.max(1) as f64,
            "ci95": mean_ci(&scores, bootstrap, seed),
            "success_rate": k as f64 / n.max(1) as f64,
            "success_ci95": [lo, hi],
            "mean_steps": rs.iter().map(|r| r.steps as f64).sum::<f64>() / n.max(1) as f64,
            "decisions": decisions,
            "replaced_fraction": rs.iter().map(|r| r.replaced).sum::<usize>() as f64 / decisions.max(1) as f64,
        });
        if p != Planner::None && base.len() == n && base.iter().zip(&rs).all(|(b, r)| b.seed == r.seed) {
            let diff: Vec<f64> = rs.iter().zip(&base).map(|(r, b)| r.score - b.score).collect();
            let better = diff.iter().filter(|d| **d > 1e-12).count();
            let worse = diff.iter().filter(|d| **d < -1e-12).count();
            v["vs_none"] = json!({
                "mean_difference": diff.iter().sum::<f64>() / n.max(1) as f64,
                "ci95": mean_ci(&diff, bootstrap, seed ^ 0x706c_616e),
                "episodes_better": better,
                "episodes_worse": worse,
            });
        }
        if p == Planner::WorldModel {
            let agreed: usize = rs.iter().filter_map(|r| r.agreed).sum();
            let regret: f64 = rs.iter().filter_map(|r| r.regret).sum();
            let random: f64 = rs.iter().filter_map(|r| r.regret_random).sum();
            v["vs_simulator"] = json!({
                "pick_agreement": agreed as f64 / decisions.max(1) as f64,
                "mean_regret_units": regret / decisions.max(1) as f64,
                "random_pick_mean_regret_units": random / decisions.max(1) as f64,
                "note": "at every decision the simulator also scored the same proposals from the true state: \
                         how often both picked the same one (chance is 1 / proposals), and how much farther \
                         from the goal (mean block-pixel distance, world units) the world model's pick ends \
                         than the simulator's best, against a pick at random",
            });
        }
        out.insert(p.name().to_string(), v);
    }
    json!({ "planners": out })
}

/// `episodes.csv`: the rows sorted by (planner, seed).
///
/// # Errors
/// The file cannot be written.
pub fn write_csv(path: &Path, rows: &[PlanRow]) -> Result<()> {
    let mut sorted: Vec<&PlanRow> = rows.iter().collect();
    sorted.sort_by(|x, y| (&x.planner, x.seed).cmp(&(&y.planner, y.seed)));
    let mut w = csv::Writer::from_path(path).with_context(|| format!("creating {}", path.display()))?;
    w.write_record([
        "planner",
        "seed",
        "score",
        "max_coverage",
        "final_coverage",
        "success",
        "steps",
        "decisions",
        "replaced",
        "agreed",
        "regret",
        "regret_random",
    ])?;
    let opt = |v: Option<String>| v.unwrap_or_default();
    for r in sorted {
        w.write_record([
            r.planner.clone(),
            r.seed.to_string(),
            format!("{:.6}", r.score),
            format!("{:.6}", r.max_coverage),
            format!("{:.6}", r.final_coverage),
            r.success.to_string(),
            r.steps.to_string(),
            r.decisions.to_string(),
            r.replaced.to_string(),
            opt(r.agreed.map(|v| v.to_string())),
            opt(r.regret.map(|v| format!("{v:.3}"))),
            opt(r.regret_random.map(|v| format!("{v:.3}"))),
        ])?;
    }
    w.flush().with_context(|| format!("writing {}", path.display()))
}

/// The table on stdout.
pub fn print_summary(res: &Value, out: &Path) {
    outln!("{:<12} {:>8} {:>17} {:>9} {:>22}", "planner", "score", "95% CI", "success", "vs none [95% CI]");
    let Some(ps) = res["planners"].as_object() else { return };
    for (name, p) in ps {
        let ci = |v: &Value| match (v[0].as_f64(), v[1].as_f64()) {
            (Some(lo), Some(hi)) => format!("[{lo:.3}, {hi:.3}]"),
            _ => "n/a".into(),
        };
        let vs = p.get("vs_none").map_or_else(String::new, |d| {
            format!("{:+.3} {}", d["mean_difference"].as_f64().unwrap_or(f64::NAN), ci(&d["ci95"]))
        });
        outln!(
            "{name:<12} {:>8.3} {:>17} {:>9.2} {vs:>22}",
            p["mean"].as_f64().unwrap_or(f64::NAN),
            ci(&p["ci95"]),
            p["success_rate"].as_f64().unwrap_or(f64::NAN),
        );
    }
    if let Some(s) = res["planners"]["world-model"].get("vs_simulator") {
        outln!(
            "world model's picks: the simulator's own in {:.0}% of decisions; {:.1} units farther from the goal \
             than the simulator's best, on average (a pick at random: {:.1})",
            100.0 * s["pick_agreement"].as_f64().unwrap_or(f64::NAN),
            s["mean_regret_units"].as_f64().unwrap_or(f64::NAN),
            s["random_pick_mean_regret_units"].as_f64().unwrap_or(f64::NAN)
        );
    }
    outln!("results: {}", out.join("results.json").display());
}

/// Writes one recorded episode's filmstrip: row 1 the real frame at each decision, row 2
/// the world model's last imagined frame of the picked proposal, row 3 the simulator's
/// (rows without frames are left out), at most 30 decisions (every n-th).
///
/// # Errors
/// The file cannot be written.
pub fn write_strip(path: &Path, rec: &[[Vec<u8>; 3]], size: usize) -> Result<()> {
    let every = rec.len().div_ceil(30).max(1);
    let rows: Vec<Vec<Vec<u8>>> = (0..3)
        .map(|r| rec.iter().step_by(every).map(|d| d[r].clone()).collect::<Vec<_>>())
        .filter(|row: &Vec<Vec<u8>>| row.iter().any(|f| !f.is_empty()))
        .collect();
    let img = reports::png::filmstrip(&rows, size, size);
    reports::png::write_png(path, &img.pixels, img.width, img.height).map_err(|e| anyhow::anyhow!(e))
}
