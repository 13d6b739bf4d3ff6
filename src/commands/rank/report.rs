//! Writing a run's report from its files, so that `rank` (at the end of a run)
//! and `evalharness report OUT` (any time later) produce the same thing:
//! `plots/*.png|svg`, `table.tex`, `summary.csv` and `report.html`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use harness::results::RankResults;
use reports::html::{Extras, report_html};
use reports::plots::write_plots;
use reports::summary::Summary;
use reports::tables::{latex_table, summary_csv};
use reports::timeplot::{TimeSeries, band, write_time_plot};
use serde_json::Value;

use crate::output::read_json;
use harness::results::Branch;

/// A checkpoint's provenance: `provenance.json` if present, else `policy.json`'s entry.
fn provenance(dir: &Path) -> String {
    let pretty = |v: &Value| serde_json::to_string_pretty(v).unwrap_or_default();
    if let Ok(v) = read_json(&dir.join("provenance.json")) {
        return pretty(&v);
    }
    match read_json(&dir.join("policy.json")) {
        Ok(v) => {
            pretty(&serde_json::json!({"epoch": v["epoch"], "step": v["step"], "training": v["provenance"]}))
        }
        Err(e) => format!("no provenance: {e:#}"),
    }
}

/// Writes the report files into `out` from `out/results.json` and `out/config.json`.
///
/// # Errors
/// Missing or malformed input files (named), or unwritable outputs.
pub fn write_report(out: &Path) -> Result<PathBuf> {
    let results = RankResults::read(&out.join("results.json"))?;
    super::check::ranges(&results).with_context(|| format!("{}", out.display()))?;
    let summary = Summary::from_results(&results);
    let config = read_json(&out.join("config.json"))?;
    let mut plots = write_plots(&out.join("plots"), &summary)?;
    let rows = harness::rows::read_rows::<harness::results::EpisodeRow>(&out.join("episodes.jsonl"))?;
    let max_steps = results.max_steps as f64;
    let series: Vec<TimeSeries> = summary
        .policies
        .iter()
        .map(|p| {
            let pick = |b: Branch| -> Vec<&[f64]> {
                rows.iter()
                    .filter(|r| r.policy == p.name && r.branch == b)
                    .map(|r| r.score_trace.as_slice())
                    .collect()
            };
            let (sim, wm) = (band(&pick(Branch::Sim)), band(&pick(Branch::WorldModel)));
            let l = sim.len().max(1) as f64;
            let steps = (1..=sim.len()).map(|k| (k as f64 * max_steps / l).round()).collect();
            TimeSeries { policy: p.name.clone(), steps, sim, world_model: wm }
        })
        .filter(|t| !t.sim.is_empty() && t.sim.len() == t.world_model.len())
        .collect();
    if !series.is_empty() {
        plots.push(write_time_plot(&out.join("plots"), &series)?);
    }
    std::fs::write(out.join("table.tex"), latex_table(&summary)).context("writing table.tex")?;
    let csv = summary_csv(&summary);
    std::fs::write(out.join("summary.csv"), csv).context("writing summary.csv")?;
    let (filmstrips, filmstrip_problems) = filmstrips(out);
    let mut prov: Vec<(String, String)> = Vec::new();
    if let Some(wm) = config["world_model"].as_str() {
        prov.push((format!("world model {wm}"), provenance(Path::new(wm))));
    }
    for c in config["checkpoints"].as_array().into_iter().flatten().filter_map(Value::as_str) {
        prov.push((format!("policy {c}"), provenance(Path::new(c))));
    }
    let t = &results.timing;
    let mut notes = vec![format!(
        "Timing (this run): wall {:.0} s; MuJoCo branch {:.0} s; world-model branch {:.0} s ({:.1} ms per generated frame); policies {:.0} s.",
        t.wall_seconds, t.sim_seconds, t.world_model_seconds, t.world_model_ms_per_frame, t.policy_seconds,
    )];
    let errs: Vec<f64> = results.policies.iter().map(|p| p.frame_scorer_mean_abs_error).collect();
    if !errs.is_empty() {
        notes.push(format!(
            "The world-model branch is scored from frames (goal mask × block colour). On real rendered frames its coverage differs from the exact polygon coverage by {:.4} on average.",
            errs.iter().sum::<f64>() / errs.len() as f64
        ));
    }
    for problem in filmstrip_problems {
        tracing::warn!("{problem}");
        notes.push(format!("Filmstrips: {problem}."));
    }
    if let Some((text, _)) = super::scene::scene_note(&results.policies) {
        notes.push(text);
    }
    notes.push("Score = max over the episode of clip(coverage / 0.95, 0, 1); success = coverage > 0.95 at some step.".into());
    let extras =
        Extras { plots, filmstrips, config: serde_json::to_string_pretty(&config)?, provenance: prov, notes };
    let html = out.join("report.html");
    std::fs::write(&html, report_html(&summary, &extras))
        .with_context(|| format!("writing {}", html.display()))?;
    Ok(html)
}

/// The filmstrips `filmstrips/index.json` lists, as (PNG, caption), and what is wrong
/// with it: an index that does not parse, entries without a `png` or `caption`, and
/// listed PNGs that are missing (each left out). No index: no filmstrips, no problem
/// (runs with `--no-report`, shards).
fn filmstrips(out: &Path) -> (Vec<(PathBuf, String)>, Vec<String>) {
    let path = out.join("filmstrips/index.json");
    if !path.exists() {
        return (Vec::new(), Vec::new());
    }
    let list = match read_json(&path) {
        Ok(Value::Array(list)) => list,
        Ok(_) => return (Vec::new(), vec![format!("{} is not a list; none shown", path.display())]),
        Err(e) => return (Vec::new(), vec![format!("{e:#}; none shown")]),
    };
    let (mut strips, mut problems) = (Vec::new(), Vec::new());
    for (i, f) in list.iter().enumerate() {
        match (f["png"].as_str(), f["caption"].as_str()) {
            (Some(png), Some(caption)) => {
                let file = out.join("filmstrips").join(png);
                if file.is_file() {
                    strips.push((file, caption.to_string()));
                } else {
                    problems.push(format!("{} (listed in {}) is missing", file.display(), path.display()));
                }
            }
            _ => problems.push(format!("{} entry {i} has no \"png\" or \"caption\"", path.display())),
        }
    }
    (strips, problems)
}

/// `evalharness tasks`: one row per run's `results.json`, Markdown on stdout and,
/// with `tex`, booktabs LaTeX in that file.
///
/// # Errors
/// A run folder without a readable `results.json` (named), or an unwritable `tex`.
pub fn tasks_table(runs: &[PathBuf], tex: Option<&Path>, force: bool) -> Result<std::process::ExitCode> {
    use reports::tasks::{TaskRow, latex_tasks, markdown_tasks};
    // Inputs before outputs: the LaTeX file is neither a run folder nor inside one (its
    // results.json would be overwritten), and an existing file is kept without --force.
    if let Some(path) = tex {
        crate::output::Inputs::new().all("RUN", runs).check(path)?;
        if std::fs::symlink_metadata(path).is_ok() && !force {
            bail!("--tex {} already exists (pass --force to replace it)", path.display());
        }
    }
    let rows = runs
        .iter()
        .map(|dir| {
            let r = RankResults::read(&dir.join("results.json"))?;
            Ok(TaskRow { summary: Summary::from_results(&r), minutes: Some(r.timing.wall_seconds / 60.0) })
        })
        .collect::<Result<Vec<_>>>()?;
    if let Some(path) = tex {
        harness::runfile::write_atomic(path, &latex_tasks(&rows))
            .map_err(|e| anyhow::anyhow!("writing {}: {}", e.path.display(), e.message))?;
    }
    out!("{}", markdown_tasks(&rows));
    Ok(std::process::ExitCode::SUCCESS)
}
