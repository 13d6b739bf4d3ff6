//! `plan`'s files and table: the episodes as CSV, the statistics
//! ([`engine::plan::results`]) on stdout, and a recorded episode's filmstrip.

use std::path::Path;

use anyhow::{Context, Result};
use engine::plan::PlanRow;
use engine::plan::results::PlanResults;

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
pub fn print_summary(res: &PlanResults, out: &Path) {
    outln!("{:<12} {:>8} {:>17} {:>9} {:>22}", "planner", "score", "95% CI", "success", "vs none [95% CI]");
    let ci =
        |v: Option<[f64; 2]>| v.map_or_else(|| "n/a".to_string(), |[lo, hi]| format!("[{lo:.3}, {hi:.3}]"));
    for (name, p) in &res.planners {
        let vs = p
            .vs_none
            .as_ref()
            .map_or_else(String::new, |d| format!("{:+.3} {}", d.mean_difference, ci(d.ci95)));
        outln!("{name:<12} {:>8.3} {:>17} {:>9.2} {vs:>22}", p.mean, ci(p.ci95), p.success_rate);
    }
    if let Some(s) = res.planners.get("world-model").and_then(|p| p.vs_simulator.as_ref()) {
        outln!(
            "world model's picks: the simulator's own in {:.0}% of decisions; {:.1} units farther from the goal \
             than the simulator's best, on average (a pick at random: {:.1})",
            100.0 * s.pick_agreement,
            s.mean_regret_units,
            s.random_pick_mean_regret_units
        )
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
