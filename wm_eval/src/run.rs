//! The evaluation itself: load the models and the dataset, choose the videos, roll
//! every model out on them, add the references and checks, and write `eval.json` and
//! a filmstrip (real row above each model's row) into a staged output folder.

use std::collections::HashMap;
use std::path::PathBuf;

use runner::output::{Inputs, Staged};
use scenarios::pusht::frame_score::FrameScorer;
use scenarios::pusht::goal_free::{self, DatasetScene, NoScene};
use world_model::data::{EpisodeData, Split};
use world_model::eval::{EvalRow, View, evaluate, persistence, round_trip};
use world_model::model::WorldModel;

use crate::report::{ByMotion, EvalFile, Sampling, WindowsUsed};
use crate::score::Scoring;
use crate::success::{self, SuccessCheck};
use crate::{Options, Windows, WmEvalError, motion, windows};

/// Bootstrap replicates of each row's SSIM interval.
const SSIM_BOOTSTRAP: usize = 2000;

/// Frames shown per filmstrip row (every 4th generated frame).
const STRIP_EVERY: usize = 4;

/// Generated frames of a short video (after its context).
const SHORT: usize = 60;

const SCORE_NOTE: &str = "whole-episode videos: the recorded actions replayed from 4 real frames; \
    score = max over the frames after the context of clip(coverage / 0.95, 0, 1), real and generated \
    frames read by the same frame scorer against the episode's goal; persistence = the last context frame";

const REFERENCES_NOTE: &str = "references on the same videos: \"persistence\" repeats the last context \
    frame (nothing moves); \"<model>:autoencoder\" (objective \"round-trip\", latent models only) is each \
    real future frame encoded and decoded by that model's autoencoder, no dynamics: the best its rollouts \
    could score, so the gap to it is the dynamics' error and its own gap to a perfect score the autoencoder's";

/// One line of the text summary.
fn row_lines(row: &EvalRow, note: &str) -> [String; 2] {
    let horizon = if row.horizon == "64" { "64-frame:" } else { "episode: " };
    let curve: Vec<String> = row.ssim_curve.iter().map(|p| format!("{}: {:.3}", p.frame, p.ssim)).collect();
    [
        format!(
            "{:<20} {:<9} {horizon} MSE {:.5} PSNR {:.2} SSIM {:.4} ({:.1} ms/frame){note}",
            row.name, row.objective, row.mse, row.psnr, row.ssim, row.ms_per_frame
        ),
        format!("{:<20} SSIM by generated frame  {}", "", curve.join("  ")),
    ]
}

/// The 64-frame rows' SSIM by block motion (said, and for `eval.json`), from the
/// dataset's state rows; a note saying why not for a dataset without them.
fn motion_breakdown(
    scene: &Result<DatasetScene, NoScene>,
    data: &EpisodeData,
    short: &[(usize, usize)],
    k: usize,
    rows: &[EvalRow],
    say: &mut dyn FnMut(&str),
) -> ByMotion {
    let scene = match scene {
        Ok(scene) if scene.len() >= data.len() => scene,
        Ok(scene) => {
            let note = format!("not available: {} state rows for {} frames", scene.len(), data.len());
            return ByMotion::Unavailable { note };
        }
        Err(why) => return ByMotion::Unavailable { note: format!("not available: {why}") },
    };
    let shape = scene.cfg.shape();
    let moved: HashMap<usize, f64> = short
        .iter()
        .map(|&(t, len)| {
            let poses = (t + k..t + k + len).map(|i| scene.state(i).block);
            (t, motion::block_motion(&shape, &scene.state(t + k - 1).block, poses))
        })
        .collect();
    let bins = motion::by_motion(rows, &moved);
    for b in &bins {
        let to = b.to.map_or_else(|| "inf".to_string(), |t| t.to_string());
        let ssim: Vec<String> = b.ssim.iter().map(|(n, s)| format!("{n} {s:.4}")).collect();
        let line = format!("block motion [{}, {to}): {:>4} videos  {}", b.from, b.videos, ssim.join("  "));
        say(line.trim_end());
    }
    ByMotion::Bins { note: motion::NOTE, bins }
}

/// Each row's SSIM interval with episodes resampled (windows of one episode overlap).
fn ssim_intervals(
    rows: &mut [EvalRow],
    episode_of: &HashMap<usize, usize>,
    seed: u64,
    say: &mut dyn FnMut(&str),
) {
    for row in rows {
        let mut by_episode: HashMap<usize, Vec<f64>> = HashMap::new();
        for v in &row.per_video {
            by_episode.entry(episode_of.get(&v.start).copied().unwrap_or(v.start)).or_default().push(v.ssim);
        }
        let mut clusters: Vec<(usize, Vec<f64>)> = by_episode.into_iter().collect();
        clusters.sort_by_key(|c| c.0);
        let clusters: Vec<Vec<f64>> = clusters.into_iter().map(|c| c.1).collect();
        row.ssim_ci = harness::metrics::bootstrap::clustered_mean_ci(&clusters, SSIM_BOOTSTRAP, seed);
        if let Some([lo, hi]) = row.ssim_ci {
            let horizon = if row.horizon == "64" { "64-frame" } else { "episode" };
            say(&format!(
                "{:<20} {horizon:<8} SSIM 95% CI [{lo:.4}, {hi:.4}] (episodes resampled)",
                row.name
            ));
        }
    }
}

/// The reference rows on the same videos: the last context frame repeated, then each
/// latent model's autoencoder rendering the real future (`view_for`: what a model reads).
fn references<'v>(
    models: &[(String, WorldModel)],
    view_for: &dyn Fn(&WorldModel) -> Option<&'v View<'v>>,
    data: &EpisodeData,
    v: &Videos,
    k: usize,
    say: &mut dyn FnMut(&str),
) -> Vec<EvalRow> {
    let mut rows = Vec::new();
    let both = [(&v.short, "64"), (&v.full, "episode")];
    for (starts, horizon) in both.iter().filter(|(s, _)| !s.is_empty()) {
        let row = persistence(data, starts, k, horizon);
        row_lines(&row, " (reference: nothing moves)").iter().for_each(|l| say(l));
        rows.push(row);
    }
    for (name, wm) in models {
        for (starts, horizon) in both.iter().filter(|(s, _)| !s.is_empty()) {
            if let Some(row) = round_trip(wm, (name, view_for(wm)), data, starts, horizon) {
                let note = " (reference: its autoencoder's rendering of the real future)";
                row_lines(&row, note).iter().for_each(|l| say(l));
                rows.push(row);
            }
        }
    }
    rows
}

/// The open-loop score rows' lines.
fn score_lines(r: &crate::score::ScoreRow) -> [String; 2] {
    let r_text = r.pearson.map_or_else(|| "n/a".to_string(), |p| format!("{p:.3}"));
    let curve: Vec<String> =
        r.coverage_curve.iter().map(|c| format!("{}: {:.2}/{:.2}", c.frame, c.real, c.imagined)).collect();
    [
        format!(
            "{:<20} open-loop score over whole episodes: real {:.3} imagined {:.3}  mean |error| {:.3}  per-video r {r_text}",
            r.name, r.real_mean, r.imagined_mean, r.mean_abs_error
        ),
        format!("{:<20} coverage real/imagined by frame  {}", "", curve.join("  ")),
    ]
}

/// The videos `wm eval` rolls out: 64-frame ones (`SHORT` generated frames after the
/// context) and whole episodes.
struct Videos {
    /// "episode" or "held-out episode".
    which: &'static str,
    short_windows: Vec<windows::Window>,
    full_windows: Vec<windows::Window>,
    /// (first context step, generated frames) of each 64-frame video.
    short: Vec<(usize, usize)>,
    /// The same for each whole-episode video.
    full: Vec<(usize, usize)>,
}

impl Videos {
    /// The videos `o` asks for in `data`, for models reading `k` context frames.
    fn choose(o: &Options, data: &EpisodeData, k: usize) -> Result<Self, WmEvalError> {
        let held: Vec<(usize, std::ops::Range<usize>)> = data
            .episodes
            .iter()
            .enumerate()
            .filter(|(i, _)| o.all_episodes || Split::HeldOut.contains(*i))
            .map(|(i, r)| (i, r.clone()))
            .collect();
        let which = if o.all_episodes { "episode" } else { "held-out episode" };
        let short_windows = if o.starts.is_empty() {
            windows::choose(&held, k + SHORT, o.episodes, o.windows, o.seed)
        } else {
            windows::at(&held, k + SHORT, &o.starts, which)?
        };
        let full_windows = windows::choose(&held, k + 1, o.full_episodes, Windows::First, o.seed);
        let short: Vec<(usize, usize)> = short_windows.iter().map(|w| (w.start, SHORT)).collect();
        let full = full_windows.iter().map(|w| (w.start, data.episodes[w.episode].len() - k)).collect();
        if short.is_empty() {
            return Err(WmEvalError::NoVideos { data: o.data.clone(), which, frames: k + SHORT });
        }
        Ok(Self { which, short_windows, full_windows, short, full })
    }
}

/// What the rollouts measured.
struct Measured {
    rows: Vec<EvalRow>,
    scores: Vec<crate::score::ScoreRow>,
    successes: Vec<crate::success::SuccessRow>,
}

/// `eval.json` of a finished evaluation.
fn eval_file(
    o: &Options,
    v: &Videos,
    models: &[(String, WorldModel)],
    m: Measured,
    by_motion: ByMotion,
    open_loop_scores_note: String,
) -> EvalFile {
    EvalFile {
        models: m.rows,
        sampling: models
            .iter()
            .map(|(name, wm)| Sampling {
                name: name.clone(),
                alpha: wm.alpha(),
                noise_scale: wm.noise_scale(),
            })
            .collect(),
        references_note: REFERENCES_NOTE,
        ssim_by_block_motion: by_motion,
        open_loop_scores: m.scores,
        open_loop_scores_note,
        open_loop_success: m.successes,
        open_loop_success_note: match &o.judge {
            Some(dir) => format!("{} (judge {})", success::SUCCESS_NOTE, dir.display()),
            None => "not measured: no --judge".to_string(),
        },
        data: o.data.clone(),
        episodes_from: if o.all_episodes {
            "all episodes (--all-episodes)"
        } else {
            "held-out episodes (index % 10 == 9)"
        },
        windows_64: if o.starts.is_empty() {
            WindowsUsed::Chosen(o.windows)
        } else {
            WindowsUsed::Given("given (--start)")
        },
        episodes_64: v.short_windows.iter().map(|w| w.episode).collect(),
        starts_64: v.short_windows.iter().map(|w| w.start).collect(),
        episodes_whole: v.full_windows.iter().map(|w| w.episode).collect(),
        videos_64: v.short.len(),
        videos_episode: v.full.len(),
        batch: o.batch,
        seed: o.seed,
        filmstrip: format!(
            "row 1: real frames of the {} {} from step {}, every {STRIP_EVERY}th after the 4 context frames; then one row per model",
            v.which, v.short_windows[0].episode, v.short[0].0
        ),
    }
}

/// The compared world models, by name, with `o`'s sampling settings.
fn load_models(o: &Options) -> Result<Vec<(String, WorldModel)>, WmEvalError> {
    let device = nn::device::selected()?;
    o.world_models
        .iter()
        .map(|p| {
            let name = policies::dir::checkpoint_name(p);
            Ok((name, runner::inputs::load_world_model(p, o.alpha, o.noise_scale, &device)?))
        })
        .collect()
}

/// Runs `wm eval` as `o` asks, handing each line of its text summary to `say` as it
/// is measured; returns the output folder.
///
/// # Errors
/// [`WmEvalError`]: an input that cannot be read, an output that cannot be written,
/// videos that cannot be made (too-short episodes, a `--start` outside them), or a
/// rollout that fails. Nothing is left at `o.out` unless the whole evaluation is written.
pub fn run(o: &Options, say: &mut dyn FnMut(&str)) -> Result<PathBuf, WmEvalError> {
    // Inputs before outputs: a misplaced --out is refused before any model is loaded.
    let inputs = o
        .world_models
        .iter()
        .fold(Inputs::new().add("--data", &o.data), |acc, m| acc.world_model("--world-model", m))
        .maybe("--judge", o.judge.as_deref());
    inputs.refuse(&o.out, ".partial")?;
    let models = load_models(o)?;
    let data = EpisodeData::load(&o.data, 96)?;
    let k = models[0].1.cfg.unet.history;
    let v = Videos::choose(o, &data, k)?;
    let (short, full) = (&v.short, &v.full);
    let staged = Staged::new(&o.out, o.force, &inputs)?;
    // The dataset's scenario and state rows, read once: for the goal-free view, the
    // open-loop scores and the SSIM by block motion.
    let scene = DatasetScene::load(&o.data)?;
    let scoring = match &scene {
        _ if full.is_empty() => Err("no whole-episode videos".to_string()),
        Ok(scene) => Ok(Scoring::new(scene, 96)),
        Err(why) => Err(why.to_string()),
    };
    if let Err(why) = &scoring
        && o.judge.is_none()
    {
        tracing::warn!("no open-loop score check: {why}");
    }
    let success = match &o.judge {
        Some(_) if full.is_empty() => return Err(WmEvalError::JudgeWithoutEpisodes),
        Some(dir) => Some(SuccessCheck::load(dir, &o.data, &data)?),
        None => None,
    };
    // Each video's episode, by its first context step (windows of one episode share it).
    let episode_of: HashMap<usize, usize> =
        v.short_windows.iter().chain(&v.full_windows).map(|w| (w.start, w.episode)).collect();
    // Goal-free models read the scenes re-rendered without the goal, and each of their
    // frames gets its episode's goal drawn back before any comparison or scoring.
    let goal_free = if models.iter().any(|(_, wm)| wm.cfg.is_goal_free()) {
        let mut inputs = data.clone();
        let scene = goal_free::strip_goal(&o.data, &scene, &mut inputs.frames, inputs.size)?;
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
    let (mut scores, mut full_videos, mut successes) = (Vec::new(), Vec::new(), Vec::new());
    let mut rows = Vec::new();
    let mut strip_rows: Vec<Vec<Vec<u8>>> = Vec::new();
    for (name, wm) in &models {
        let view = view_for(wm);
        tracing::info!(model = %name, videos = short.len(), "64-frame rollouts");
        let (row, videos) = evaluate(wm, (name, view), &data, short, "64", o.batch, o.seed)?;
        if strip_rows.is_empty() {
            strip_rows.push(videos[0].real.iter().step_by(STRIP_EVERY).cloned().collect());
        }
        strip_rows.push(videos[0].generated.iter().step_by(STRIP_EVERY).cloned().collect());
        row_lines(&row, "").iter().for_each(|l| say(l));
        rows.push(row);
        if !full.is_empty() {
            tracing::info!(model = %name, videos = full.len(), "full-episode rollouts");
            let (row, videos) = evaluate(wm, (name, view), &data, full, "episode", o.batch, o.seed)?;
            row_lines(&row, "").iter().for_each(|l| say(l));
            rows.push(row);
            if let Ok(sc) = &scoring {
                scores.push(sc.row(name, &videos));
            }
            if let Some(check) = &success {
                let row = check.row(name, &data, &videos, k, |start| episode_of[&start]);
                success::lines(&row).iter().for_each(|l| say(l));
                successes.push(row);
            }
            full_videos = videos;
        }
    }
    rows.extend(references(&models, &view_for, &data, &v, k, say));
    if let Ok(sc) = &scoring {
        scores.push(sc.persistence(&data, &full_videos, k));
        scores.iter().flat_map(score_lines).for_each(|l| say(&l));
    }
    ssim_intervals(&mut rows, &episode_of, o.seed, say);
    let by_motion = motion_breakdown(&scene, &data, short, k, &rows, say);
    let strip = reports::png::filmstrip(&strip_rows, data.size, data.size);
    reports::png::write_png(&staged.file("filmstrip.png"), &strip.pixels, strip.width, strip.height)?;
    let scores_note = scoring.as_ref().err().cloned().unwrap_or_else(|| SCORE_NOTE.into());
    let measured = Measured { rows, scores, successes };
    let file = eval_file(o, &v, &models, measured, by_motion, scores_note);
    file.write(&staged.file("eval.json"))?;
    Ok(staged.commit()?)
}
