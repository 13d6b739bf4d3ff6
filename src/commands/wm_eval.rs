//! `evalharness wm eval`: compares world models' rollouts with held-out episodes
//! and writes `eval.json` and a filmstrip (real row above each model's row).

use std::collections::HashMap;
use std::process::ExitCode;

use anyhow::{Result, bail};
use scenarios::pusht::frame_score::FrameScorer;
use serde_json::json;
use world_model::data::{EpisodeData, Split};
use world_model::eval::{EvalRow, View, evaluate, persistence, round_trip};
use world_model::model::WorldModel;

use super::goal_free;
use super::goal_free::DatasetScene;
use super::wm_eval_motion;
use super::wm_eval_score::Scoring;
use super::wm_eval_success::{self, SuccessCheck};
use super::wm_eval_windows;
use crate::cli::Windows;
use crate::cli::WmEvalArgs;
use crate::output::{Staged, write_json};

/// Bootstrap replicates of each row's SSIM interval.
const SSIM_BOOTSTRAP: usize = 2000;

/// Frames shown per filmstrip row (every 4th generated frame).
const STRIP_EVERY: usize = 4;

const SCORE_NOTE: &str = "whole-episode videos: the recorded actions replayed from 4 real frames; \
    score = max over the frames after the context of clip(coverage / 0.95, 0, 1), real and generated \
    frames read by the same frame scorer against the episode's goal; persistence = the last context frame";

const REFERENCES_NOTE: &str = "references on the same videos: \"persistence\" repeats the last context \
    frame (nothing moves); \"<model>:autoencoder\" (objective \"round-trip\", latent models only) is each \
    real future frame encoded and decoded by that model's autoencoder, no dynamics: the best its rollouts \
    could score, so the gap to it is the dynamics' error and its own gap to a perfect score the autoencoder's";

/// One line of the text summary.
fn print_row(row: &EvalRow, note: &str) {
    let horizon = if row.horizon == "64" { "64-frame:" } else { "episode: " };
    outln!(
        "{:<20} {:<9} {horizon} MSE {:.5} PSNR {:.2} SSIM {:.4} ({:.1} ms/frame){note}",
        row.name,
        row.objective,
        row.mse,
        row.psnr,
        row.ssim,
        row.ms_per_frame
    );
    let curve: Vec<String> = row.ssim_curve.iter().map(|p| format!("{}: {:.3}", p.frame, p.ssim)).collect();
    outln!("{:<20} SSIM by generated frame  {}", "", curve.join("  "));
}

/// The 64-frame rows' SSIM by block motion (printed, and for `eval.json`), from the
/// dataset's state rows; a note saying why not for a dataset without them.
fn motion_breakdown(
    scene: &Result<DatasetScene, String>,
    data: &EpisodeData,
    short: &[(usize, usize)],
    k: usize,
    rows: &[EvalRow],
) -> serde_json::Value {
    let scene = match scene {
        Ok(scene) if scene.len() >= data.len() => scene,
        Ok(scene) => {
            return json!({"note": format!("not available: {} state rows for {} frames", scene.len(), data.len())});
        }
        Err(why) => return json!({"note": format!("not available: {why}")}),
    };
    let shape = scene.cfg.shape();
    let motion: HashMap<usize, f64> = short
        .iter()
        .map(|&(t, len)| {
            let poses = (t + k..t + k + len).map(|i| scene.state(i).block);
            (t, wm_eval_motion::block_motion(&shape, &scene.state(t + k - 1).block, poses))
        })
        .collect();
    let bins = wm_eval_motion::by_motion(rows, &motion);
    for b in &bins {
        let to = b.to.map_or_else(|| "inf".to_string(), |t| t.to_string());
        let ssim: Vec<String> = b.ssim.iter().map(|(n, s)| format!("{n} {s:.4}")).collect();
        let line = format!("block motion [{}, {to}): {:>4} videos  {}", b.from, b.videos, ssim.join("  "));
        outln!("{}", line.trim_end());
    }
    json!({"note": wm_eval_motion::NOTE, "bins": bins})
}

/// `evalharness wm eval`.
pub fn run(a: &WmEvalArgs) -> Result<ExitCode> {
    // Inputs before outputs: a misplaced --out is refused before any model is loaded.
    let inputs = a
        .world_models
        .iter()
        .fold(crate::output::Inputs::new().add("--data", &a.data), |acc, m| {
            acc.world_model("--world-model", m)
        })
        .maybe("--judge", a.judge.as_deref());
    inputs.refuse(&a.out, ".partial")?;
    let device = nn::device::selected()?;
    let models: Vec<(String, WorldModel)> = a
        .world_models
        .iter()
        .map(|p| {
            let name = policies::dir::checkpoint_name(p);
            Ok((name, runner::inputs::load_world_model(p, a.alpha, a.noise_scale, &device)?))
        })
        .collect::<Result<_>>()?;
    let data = EpisodeData::load(&a.data, 96)?;
    let k = models[0].1.cfg.unet.history;
    let held: Vec<(usize, std::ops::Range<usize>)> = data
        .episodes
        .iter()
        .enumerate()
        .filter(|(i, _)| a.all_episodes || Split::HeldOut.contains(*i))
        .map(|(i, r)| (i, r.clone()))
        .collect();
    let which = if a.all_episodes { "episode" } else { "held-out episode" };
    let short_windows = if a.starts.is_empty() {
        wm_eval_windows::choose(&held, k + 60, a.episodes, a.windows, a.seed)
    } else {
        wm_eval_windows::at(&held, k + 60, &a.starts, which).map_err(anyhow::Error::msg)?
    };
    let full_windows = wm_eval_windows::choose(&held, k + 1, a.full_episodes, Windows::First, a.seed);
    let short: Vec<(usize, usize)> = short_windows.iter().map(|w| (w.start, 60)).collect();
    let full: Vec<(usize, usize)> =
        full_windows.iter().map(|w| (w.start, data.episodes[w.episode].len() - k)).collect();
    if short.is_empty() {
        bail!("{}: no {which} has {} frames", a.data.display(), k + 60);
    }
    let staged = Staged::new(&a.out, a.force, &inputs)?;
    // The dataset's scenario and state rows, read once: for the goal-free view, the
    // open-loop scores and the SSIM by block motion.
    let scene = DatasetScene::load(&a.data)?;
    let scoring = match &scene {
        _ if full.is_empty() => Err("no whole-episode videos".to_string()),
        Ok(scene) => Ok(Scoring::new(scene, 96)),
        Err(why) => Err(why.clone()),
    };
    if let Err(why) = &scoring
        && a.judge.is_none()
    {
        tracing::warn!("no open-loop score check: {why}");
    }
    let success = match &a.judge {
        Some(_) if full.is_empty() => {
            bail!("--judge reads whole-episode videos: give --full-episodes of at least 1")
        }
        Some(dir) => Some(SuccessCheck::load(dir, &a.data, &data)?),
        None => None,
    };
    // Each video's episode, by its first context step (windows of one episode share it).
    let episode_of: HashMap<usize, usize> =
        short_windows.iter().chain(&full_windows).map(|w| (w.start, w.episode)).collect();
    let mut successes = Vec::new();
    // Goal-free models read the scenes re-rendered without the goal, and each of their
    // frames gets its episode's goal drawn back before any comparison or scoring.
    let goal_free = if models.iter().any(|(_, wm)| wm.cfg.is_goal_free()) {
        let mut inputs = data.clone();
        let scene = goal_free::strip_goal(&a.data, &scene, &mut inputs)?;
        Some((inputs, scene))
    } else {
        None
    };
    let complete = |t: usize, frames: &mut [Vec<u8>]| {
        if let Some((_, scene)) = &goal_free {
            let scorer = FrameScorer::new(&scene.cfg, &scene.goal(t), data.size);
            frames.iter_mut().for_each(|f| scorer.draw_goal(f));
        }
    };
    let view = goal_free.as_ref().map(|(inputs, _)| View { inputs, complete: &complete });
    // What each model reads: the goal-free view for a goal-free model, the dataset otherwise.
    let view_for = |wm: &WorldModel| if wm.cfg.is_goal_free() { view.as_ref() } else { None };
    let (mut scores, mut full_videos) = (Vec::new(), Vec::new());
    let mut rows = Vec::new();
    let mut strip_rows: Vec<Vec<Vec<u8>>> = Vec::new();
    for (name, wm) in &models {
        let view = view_for(wm);
        tracing::info!(model = %name, videos = short.len(), "64-frame rollouts");
        let (row, videos) = evaluate(wm, (name, view), &data, &short, "64", a.batch, a.seed)?;
        if strip_rows.is_empty() {
            strip_rows.push(videos[0].real.iter().step_by(STRIP_EVERY).cloned().collect());
        }
        strip_rows.push(videos[0].generated.iter().step_by(STRIP_EVERY).cloned().collect());
        print_row(&row, "");
        rows.push(row);
        if !full.is_empty() {
            tracing::info!(model = %name, videos = full.len(), "full-episode rollouts");
            let (row, videos) = evaluate(wm, (name, view), &data, &full, "episode", a.batch, a.seed)?;
            print_row(&row, "");
            rows.push(row);
            if let Ok(sc) = &scoring {
                scores.push(sc.row(name, &videos));
            }
            if let Some(check) = &success {
                let row = check.row(name, &data, &videos, k, |start| episode_of[&start]);
                wm_eval_success::print(&row);
                successes.push(row);
            }
            full_videos = videos;
        }
    }
    for (starts, horizon) in [(&short, "64"), (&full, "episode")] {
        if !starts.is_empty() {
            let row = persistence(&data, starts, k, horizon);
            print_row(&row, " (reference: nothing moves)");
            rows.push(row);
        }
    }
    for (name, wm) in &models {
        let view = view_for(wm);
        for (starts, horizon) in [(&short, "64"), (&full, "episode")] {
            if starts.is_empty() {
                continue;
            }
            if let Some(row) = round_trip(wm, (name, view), &data, starts, horizon) {
                print_row(&row, " (reference: its autoencoder's rendering of the real future)");
                rows.push(row);
            }
        }
    }
    if let Ok(sc) = &scoring {
        scores.push(sc.persistence(&data, &full_videos, k));
        for r in &scores {
            let r_text = r.pearson.map_or_else(|| "n/a".to_string(), |p| format!("{p:.3}"));
            outln!(
                "{:<20} open-loop score over whole episodes: real {:.3} imagined {:.3}  mean |error| {:.3}  per-video r {r_text}",
                r.name,
                r.real_mean,
                r.imagined_mean,
                r.mean_abs_error
            );
            let curve: Vec<String> = r
                .coverage_curve
                .iter()
                .map(|c| format!("{}: {:.2}/{:.2}", c.frame, c.real, c.imagined))
                .collect();
            outln!("{:<20} coverage real/imagined by frame  {}", "", curve.join("  "));
        }
    }
    // SSIM intervals by episode: resample episodes, since windows of one episode overlap.
    for row in &mut rows {
        let mut by_episode: HashMap<usize, Vec<f64>> = HashMap::new();
        for v in &row.per_video {
            by_episode.entry(episode_of.get(&v.start).copied().unwrap_or(v.start)).or_default().push(v.ssim);
        }
        let mut clusters: Vec<(usize, Vec<f64>)> = by_episode.into_iter().collect();
        clusters.sort_by_key(|c| c.0);
        let clusters: Vec<Vec<f64>> = clusters.into_iter().map(|c| c.1).collect();
        row.ssim_ci = harness::metrics::bootstrap::clustered_mean_ci(&clusters, SSIM_BOOTSTRAP, a.seed);
        if let Some([lo, hi]) = row.ssim_ci {
            let horizon = if row.horizon == "64" { "64-frame" } else { "episode" };
            outln!("{:<20} {horizon:<8} SSIM 95% CI [{lo:.4}, {hi:.4}] (episodes resampled)", row.name);
        }
    }
    let by_motion = motion_breakdown(&scene, &data, &short, k, &rows);
    let strip = reports::png::filmstrip(&strip_rows, data.size, data.size);
    reports::png::write_png(&staged.file("filmstrip.png"), &strip.pixels, strip.width, strip.height)?;
    write_json(
        &staged.file("eval.json"),
        &json!({
            "models": rows,
            "sampling": models.iter().map(|(name, wm)| json!({"name": name, "alpha": wm.alpha(),
                "noise_scale": wm.noise_scale()})).collect::<Vec<_>>(),
            "references_note": REFERENCES_NOTE,
            "ssim_by_block_motion": by_motion,
            "open_loop_scores": scores,
            "open_loop_scores_note": scoring.as_ref().err().cloned().unwrap_or_else(|| SCORE_NOTE.into()),
            "open_loop_success": successes,
            "open_loop_success_note": match &a.judge {
                Some(dir) => format!("{} (judge {})", wm_eval_success::SUCCESS_NOTE, dir.display()),
                None => "not measured: no --judge".to_string(),
            },
            "data": a.data,
            "episodes_from": if a.all_episodes { "all episodes (--all-episodes)" } else { "held-out episodes (index % 10 == 9)" },
            "windows_64": if a.starts.is_empty() { json!(a.windows) } else { json!("given (--start)") },
            "episodes_64": short_windows.iter().map(|w| w.episode).collect::<Vec<_>>(),
            "starts_64": short_windows.iter().map(|w| w.start).collect::<Vec<_>>(),
            "episodes_whole": full_windows.iter().map(|w| w.episode).collect::<Vec<_>>(),
            "videos_64": short.len(), "videos_episode": full.len(), "batch": a.batch, "seed": a.seed,
            "filmstrip": format!("row 1: real frames of the {which} {} from step {}, every {STRIP_EVERY}th after the 4 context frames; then one row per model", short_windows[0].episode, short[0].0),
        }),
    )?;
    let out = staged.commit()?;
    outln!("-> {}", out.display());
    Ok(ExitCode::SUCCESS)
}
