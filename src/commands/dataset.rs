//! `evalharness dataset info`: what a replay-buffer dataset holds.
//!
//! Episode scores come from `data/success` when the dataset has it (Lift: an
//! episode scores 1 if the cube was lifted at any step); from `data/coverage`
//! when it has that (Push-T, ours do); otherwise from `data/state` when its columns include the goal pose (Push-T
//! GPC layout: agent xy, block xyθ, goal xyθ), as the coverage before each
//! action; otherwise they are reported as unavailable rather than guessed.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context, Result};
use harness::replay::ReplayReader;
use scenarios::pusht::{Pose2, PushTConfig, score};
use serde_json::{Value, json};

/// Per-episode score and success from per-step coverage.
fn episode_scores(r: &ReplayReader, coverage: &[f64], threshold: f64) -> Vec<(f64, bool)> {
    (0..r.episodes())
        .map(|i| {
            let best = r.episode_range(i).map(|t| coverage[t]).fold(0.0f64, f64::max);
            ((best / threshold).clamp(0.0, 1.0), best > threshold)
        })
        .collect()
}

fn stats(values: &[f64]) -> Value {
    let n = values.len().max(1) as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    let min = values.iter().copied().fold(f64::INFINITY, f64::min);
    let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    json!({"mean": mean, "std": var.sqrt(), "min": min, "max": max})
}

/// Runs the command.
pub fn info(path: &Path, as_json: bool) -> Result<ExitCode> {
    let r = ReplayReader::open(path).with_context(|| format!("opening dataset {}", path.display()))?;
    let cfg = PushTConfig::default();
    // A Push-T dataset's own success coverage; the default for others (which record
    // data/success, so it is not read) and for datasets without evalharness attributes.
    let recorded =
        harness::replay::attrs::DatasetAttrs::from_root(path, &r.attrs)?.and_then(|a| a.scenario_config);
    let threshold = recorded
        .and_then(|c| serde_json::from_value::<PushTConfig>(c).ok())
        .map_or(cfg.task.success_coverage, |c| c.task.success_coverage);
    let state_dim = r.state.row_len();
    let success = r.extra("success")?;
    let (source, coverage) = if success.is_some() {
        ("data/success", None)
    } else if let Some(c) = r.extra("coverage")? {
        ("data/coverage", Some(c))
    } else if state_dim >= 8 {
        let s = r.state.read_f64()?;
        let c = s
            .chunks(state_dim)
            .map(|row| {
                let block = Pose2::new(row[2], row[3], row[4]);
                let goal = Pose2::new(row[5], row[6], row[7]);
                score(&cfg, &block, &goal).coverage
            })
            .collect();
        ("data/state (coverage before each action)", Some(c))
    } else {
        ("unavailable (no data/coverage, no goal in data/state)", None)
    };
    let lengths: Vec<f64> = (0..r.episodes()).map(|i| r.episode_range(i).len() as f64).collect();
    let shape = r.img.shape();
    let mut out = json!({
        "path": path.display().to_string(),
        "episodes": r.episodes(),
        "steps": r.steps(),
        "steps_per_episode": stats(&lengths),
        "image": [shape[1], shape[2], shape[3]],
        "action_dim": r.action.row_len(),
        "state_dim": state_dim,
        "score_source": source,
    });
    let scores = match (&success, coverage) {
        (Some(s), _) => Some(
            episode_scores(&r, s, 0.5).into_iter().map(|(_, hit)| (f64::from(u8::from(hit)), hit)).collect(),
        ),
        (None, Some(c)) => Some(episode_scores(&r, &c, threshold)),
        (None, None) => None,
    };
    if let Some(scores) = scores {
        let values: Vec<f64> = scores.iter().map(|s| s.0).collect();
        let mut score = stats(&values);
        score["success_rate"] =
            json!(scores.iter().filter(|s| s.1).count() as f64 / scores.len().max(1) as f64);
        out["score"] = score;
        // Per-behaviour breakdown when the dataset records who acted in each episode.
        let eps = harness::replay::origin::episodes_in(path, &r.attrs)?;
        if eps.len() == scores.len() {
            let mut by: BTreeMap<String, Vec<(f64, bool)>> = BTreeMap::new();
            for (e, s) in eps.iter().zip(&scores) {
                let name = e.behaviour.clone().unwrap_or_else(|| "unknown".into());
                by.entry(name).or_default().push(*s);
            }
            let b: serde_json::Map<String, Value> = by
                .into_iter()
                .map(|(k, v)| {
                    let n = v.len() as f64;
                    let mean = v.iter().map(|s| s.0).sum::<f64>() / n;
                    let succ = v.iter().filter(|s| s.1).count() as f64 / n;
                    (k, json!({"episodes": v.len(), "mean_score": mean, "success_rate": succ}))
                })
                .collect();
            out["behaviours"] = Value::Object(b);
        }
    }
    if as_json {
        outln!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        print_text(&out);
    }
    Ok(ExitCode::SUCCESS)
}

fn print_text(v: &Value) {
    let f = |x: &Value| x.as_f64().unwrap_or(f64::NAN);
    let s = &v["steps_per_episode"];
    outln!("dataset    {}", v["path"].as_str().unwrap_or(""));
    outln!(
        "episodes   {}   steps {} (per episode: min {}, mean {:.1}, max {})",
        v["episodes"],
        v["steps"],
        f(&s["min"]),
        f(&s["mean"]),
        f(&s["max"])
    );
    outln!("arrays     img {}   action {}   state {}", v["image"], v["action_dim"], v["state_dim"]);
    match v.get("score") {
        Some(sc) => outln!(
            "score      mean {:.3}  std {:.3}  min {:.3}  max {:.3}  success {:.1}%   (from {})",
            f(&sc["mean"]),
            f(&sc["std"]),
            f(&sc["min"]),
            f(&sc["max"]),
            100.0 * f(&sc["success_rate"]),
            v["score_source"].as_str().unwrap_or("")
        ),
        None => outln!("score      {}", v["score_source"].as_str().unwrap_or("")),
    }
    if let Some(b) = v["behaviours"].as_object() {
        for (name, s) in b {
            outln!(
                "behaviour  {name:<8} {:>5} episodes   mean score {:.3}   success {:.1}%",
                s["episodes"],
                f(&s["mean_score"]),
                100.0 * f(&s["success_rate"])
            );
        }
    }
}
