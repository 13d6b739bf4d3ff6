//! `evalharness dataset info`: what a replay-buffer dataset holds.
//!
//! Episode scores come from `data/success` when the dataset has it (Lift: an
//! episode scores 1 if the cube was lifted at any step); from `data/coverage`
//! when it has that (Push-T, ours do); otherwise from `data/state` when its columns include the goal pose (Push-T
//! GPC layout: agent xy, block xyθ, goal xyθ), as the coverage before each
//! action; otherwise they are reported as unavailable rather than guessed.

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::{Context, Result, SimError};
use crate::say;
use harness::replay::ReplayReader;
use scenarios::pusht::{Pose2, PushTConfig, score};
use serde::Serialize;

/// Per-episode score and success from per-step coverage.
fn episode_scores(r: &ReplayReader, coverage: &[f64], threshold: f64) -> Vec<(f64, bool)> {
    (0..r.episodes())
        .map(|i| {
            let best = r.episode_range(i).map(|t| coverage[t]).fold(0.0f64, f64::max);
            ((best / threshold).clamp(0.0, 1.0), best > threshold)
        })
        .collect()
}

/// Mean, spread and range of a set of values.
#[derive(Debug, Serialize)]
struct Stats {
    mean: f64,
    std: f64,
    min: f64,
    max: f64,
}

fn stats(values: &[f64]) -> Stats {
    let n = values.len().max(1) as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    let min = values.iter().copied().fold(f64::INFINITY, f64::min);
    let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Stats { mean, std: var.sqrt(), min, max }
}

/// The episodes' scores: their statistics and success rate.
#[derive(Debug, Serialize)]
struct Scores {
    #[serde(flatten)]
    stats: Stats,
    success_rate: f64,
}

/// One behaviour's episodes.
#[derive(Debug, Serialize)]
struct Behaviour {
    episodes: usize,
    mean_score: f64,
    success_rate: f64,
}

/// What `dataset info` reports (`--json` writes it with keys in alphabetical order).
#[derive(Debug, Serialize)]
struct Info {
    path: String,
    episodes: usize,
    steps: usize,
    steps_per_episode: Stats,
    image: [usize; 3],
    action_dim: usize,
    state_dim: usize,
    score_source: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    score: Option<Scores>,
    #[serde(skip_serializing_if = "Option::is_none")]
    behaviours: Option<BTreeMap<String, Behaviour>>,
}

/// Runs the command.
pub fn info(path: &Path, as_json: bool, say: &mut dyn FnMut(&str)) -> Result<bool> {
    let r = ReplayReader::open(path).with_context(|| format!("opening dataset {}", path.display()))?;
    let cfg = PushTConfig::default();
    // A Push-T dataset's own success coverage; the default for others (which record
    // data/success, so it is not read) and for datasets without evalharness attributes.
    let attrs = harness::replay::attrs::DatasetAttrs::from_root(path, &r.attrs)?.unwrap_or_default();
    let threshold = attrs
        .scenario_config
        .clone()
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
    let scores = match (&success, coverage) {
        (Some(s), _) => Some(
            episode_scores(&r, s, 0.5).into_iter().map(|(_, hit)| (f64::from(u8::from(hit)), hit)).collect(),
        ),
        (None, Some(c)) => Some(episode_scores(&r, &c, threshold)),
        (None, None) => None,
    };
    let rate = |s: &[(f64, bool)]| s.iter().filter(|s| s.1).count() as f64 / s.len().max(1) as f64;
    let score = scores.as_ref().map(|scores: &Vec<(f64, bool)>| {
        let values: Vec<f64> = scores.iter().map(|s| s.0).collect();
        Scores { stats: stats(&values), success_rate: rate(scores) }
    });
    // Per-behaviour breakdown when the dataset records who acted in each episode.
    let eps = &attrs.episodes;
    let behaviours = scores.as_ref().filter(|s| eps.len() == s.len()).map(|scores| {
        let mut by: BTreeMap<String, Vec<(f64, bool)>> = BTreeMap::new();
        for (e, s) in eps.iter().zip(scores) {
            by.entry(e.behaviour.clone().unwrap_or_else(|| "unknown".into())).or_default().push(*s);
        }
        by.into_iter()
            .map(|(k, v)| {
                let mean_score = v.iter().map(|s| s.0).sum::<f64>() / v.len() as f64;
                (k, Behaviour { episodes: v.len(), mean_score, success_rate: rate(&v) })
            })
            .collect()
    });
    let shape = r.img.shape();
    let out = Info {
        path: path.display().to_string(),
        episodes: r.episodes(),
        steps: r.steps(),
        steps_per_episode: stats(&lengths),
        image: [shape[1], shape[2], shape[3]],
        action_dim: r.action.row_len(),
        state_dim,
        score_source: source,
        score,
        behaviours,
    };
    if as_json {
        // Through a JSON value, whose maps keep keys in alphabetical order.
        let value = serde_json::to_value(&out).map_err(SimError::Encode)?;
        say!(say, "{}", serde_json::to_string_pretty(&value).map_err(SimError::Encode)?);
    } else {
        print_text(&out, say);
    }
    Ok(true)
}

fn print_text(v: &Info, say: &mut dyn FnMut(&str)) {
    let s = &v.steps_per_episode;
    say!(say, "dataset    {}", v.path);
    say!(
        say,
        "episodes   {}   steps {} (per episode: min {}, mean {:.1}, max {})",
        v.episodes,
        v.steps,
        s.min,
        s.mean,
        s.max
    );
    let [h, w, c] = v.image;
    say!(say, "arrays     img [{h},{w},{c}]   action {}   state {}", v.action_dim, v.state_dim);
    match &v.score {
        Some(sc) => say!(
            say,
            "score      mean {:.3}  std {:.3}  min {:.3}  max {:.3}  success {:.1}%   (from {})",
            sc.stats.mean,
            sc.stats.std,
            sc.stats.min,
            sc.stats.max,
            100.0 * sc.success_rate,
            v.score_source
        ),
        None => say!(say, "score      {}", v.score_source),
    }
    for (name, s) in v.behaviours.iter().flatten() {
        say!(
            say,
            "behaviour  {name:<8} {:>5} episodes   mean score {:.3}   success {:.1}%",
            s.episodes,
            s.mean_score,
            100.0 * s.success_rate
        );
    }
}
