//! A run's report, written from its files, so that `rank` (at the end of a run),
//! `merge` and `evalharness report OUT` (any time later) produce the same thing:
//! `plots/*.png|svg`, `table.tex`, `summary.csv` and `report.html`.

use std::path::{Path, PathBuf};

use harness::results::{Branch, EpisodeRow, RankResults};
use reports::html::{Extras, report_html};
use reports::plots::write_plots;
use reports::summary::Summary;
use reports::tables::{latex_table, summary_csv};
use reports::timeplot::{TimeSeries, band, write_time_plot};
use serde::Serialize;

use crate::config::RankConfig;
use crate::error::RunError;

/// A checkpoint's provenance as the report shows it: `provenance.json` if present,
/// else `policy.json`'s epoch, step and provenance entry.
fn provenance(dir: &Path) -> String {
    /// What the report shows of a `policy.json`.
    #[derive(Serialize)]
    struct Shown<'a> {
        epoch: u64,
        step: u64,
        training: &'a policies::provenance::PolicyProvenance,
    }
    if let Ok(text) = std::fs::read_to_string(dir.join("provenance.json"))
        && let Ok(v) = serde_json::from_str::<serde_json::Value>(&text)
    {
        return serde_json::to_string_pretty(&v).unwrap_or_default();
    }
    match policies::dir::read_policy_file(dir) {
        Ok(f) => {
            let shown = Shown { epoch: f.epoch, step: f.step, training: &f.provenance };
            serde_json::to_string_pretty(&shown).unwrap_or_default()
        }
        Err(e) => format!("no provenance: {e}"),
    }
}

/// Writes the report files into `out` from `out/results.json` and `out/config.json`.
///
/// # Errors
/// [`RunError`]: missing or malformed input files (named), numbers no run can produce,
/// or unwritable outputs.
pub fn write_report(out: &Path) -> Result<PathBuf, RunError> {
    let results = RankResults::read(&out.join("results.json"))?;
    crate::check::ranges(&results)?;
    let summary = Summary::from_results(&results);
    let config: RankConfig = crate::config::read(&out.join("config.json"))?;
    let mut plots = write_plots(&out.join("plots"), &summary)?;
    let rows = harness::rows::read_rows::<EpisodeRow>(&out.join("episodes.jsonl"))?;
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
        plots.push(write_time_plot(&out.join("plots"), &series, &summary.simulator)?);
    }
    let table = out.join("table.tex");
    std::fs::write(&table, latex_table(&summary))
        .map_err(RunError::file(format!("writing {}", table.display())))?;
    let csv = out.join("summary.csv");
    std::fs::write(&csv, summary_csv(&summary))
        .map_err(RunError::file(format!("writing {}", csv.display())))?;
    let (filmstrips, filmstrip_problems) = filmstrips(out);
    let mut prov: Vec<(String, String)> = Vec::new();
    prov.push((format!("world model {}", config.world_model.display()), provenance(&config.world_model)));
    for c in &config.checkpoints {
        prov.push((format!("policy {}", c.display()), provenance(c)));
    }
    let t = &results.timing;
    let mut notes = vec![format!(
        "Timing (this run): wall {:.0} s; {} branch {:.0} s; world-model branch {:.0} s ({:.1} ms per generated frame); policies {:.0} s.",
        t.wall_seconds,
        results.simulator(),
        t.sim_seconds,
        t.world_model_seconds,
        t.world_model_ms_per_frame,
        t.policy_seconds,
    )];
    let errs: Vec<f64> = results.policies.iter().map(|p| p.frame_scorer_mean_abs_error).collect();
    if !errs.is_empty() {
        let judge = config.judge.as_ref().map_or("the task's own judge".to_string(), |j| {
            format!("the learned judge {}", j.path.display())
        });
        notes.push(format!(
            "The world-model branch is scored from its frames by {judge}. On the simulator's real frames its score differs from the exact one by {:.4} on average.",
            errs.iter().sum::<f64>() / errs.len() as f64
        ));
    }
    for problem in filmstrip_problems {
        tracing::warn!("{problem}");
        notes.push(format!("Filmstrips: {problem}."));
    }
    if let Some((text, _)) = reports::scene::scene_note(&results.policies, results.simulator()) {
        notes.push(text);
    }
    // Written by the run from version 3 of results.json; an earlier run's is not known here.
    if let Some(scoring) = &results.scoring {
        notes.push(format!("An episode's score: {scoring}."));
    }
    let config = serde_json::to_string_pretty(&config).unwrap_or_default();
    let extras = Extras { plots, filmstrips, config, provenance: prov, notes };
    let html = out.join("report.html");
    std::fs::write(&html, report_html(&summary, &extras))
        .map_err(RunError::file(format!("writing {}", html.display())))?;
    Ok(html)
}

/// The filmstrips `filmstrips/index.json` lists, as (PNG, caption), and what is wrong
/// with it: an index that does not parse (none shown) and listed PNGs that are missing
/// (each left out). No index: no filmstrips, no problem (runs with `--no-report`,
/// shards).
fn filmstrips(out: &Path) -> (Vec<(PathBuf, String)>, Vec<String>) {
    let path = out.join("filmstrips/index.json");
    if !path.exists() {
        return (Vec::new(), Vec::new());
    }
    let list = match crate::filmstrips::read(&path) {
        Ok(list) => list,
        Err(e) => return (Vec::new(), vec![format!("{e}; none shown")]),
    };
    let (mut strips, mut problems) = (Vec::new(), Vec::new());
    for f in list {
        let file = out.join("filmstrips").join(&f.png);
        if file.is_file() {
            strips.push((file, f.caption));
        } else {
            problems.push(format!("{} (listed in {}) is missing", file.display(), path.display()));
        }
    }
    (strips, problems)
}
