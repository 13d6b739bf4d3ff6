//! `evalharness simulate --policy DIR`: MuJoCo scores of policy checkpoints —
//! what users do today without a world model, and how the shipped policy set's
//! checkpoints get their measured scores (`--record-scores`).

use std::time::Instant;

use std::sync::Arc;

use crate::error::{Context, Result, SimError, refuse};
use crate::{Invocation, say};
use engine::{Observe, Setup, Start, Timing, sim_branch};
use nn::frames::{frames_to_tensor, tensor_to_frames};
use policies::dir::checkpoint_dirs;
use policies::provenance::{MujocoScore, PolicyScores};
use serde_json::{Value, json};
use world_model::model::WorldModel;

use crate::args::SimulateArgs;
use crate::collect::load_task;
use harness::results::EpisodeRow;
use harness::rows::append_rows;
use harness::summarise::branch_stats;
use policies::kinds::{expectations, load_any};
use runner::command::write_json;
use runner::output::Staged;

/// Runs every checkpoint under `--policy` in MuJoCo.
pub fn run(args: &SimulateArgs, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<bool> {
    let c = &args.common;
    let dir = std::path::Path::new(&args.policy);
    let task = load_task(&c.scenario)?;
    let max_steps = c.max_steps.map_or(task.max_steps(), |m| m as usize);
    let setup = Setup::new(task.as_ref(), args.seed.unwrap_or(0), max_steps, None);
    let device = nn::device::selected()?;
    let dirs = checkpoint_dirs(dir)?;
    let observe = match &args.observe_through {
        Some(wm) => Some(through_autoencoder(wm, task.observation_spec().image_size, &device)?),
        None => None,
    };
    if args.record_scores && observe.is_some() {
        refuse!(
            "--record-scores records MuJoCo scores on real frames; it cannot be given with --observe-through"
        );
    }
    let out = Staged::new(&args.out, c.force, &args.inputs())?;
    let expect = expectations(task.as_ref());
    let seeds: Vec<u64> = harness::seed::range(c.seed_start, c.episodes)?.collect();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(c.jobs.max(1))
        .build()
        .map_err(|e| SimError::Refused(format!("starting threads: {e}")))?;
    let pb = runner::progress::bar((dirs.len() as u64) * c.episodes, "simulate", inv.quiet);
    let jsonl = out.file("episodes.jsonl");
    let mut summary: Vec<Value> = Vec::new();
    let mut ok = true;
    for d in &dirs {
        let name = policies::dir::checkpoint_name(d);
        let started = Instant::now();
        let rows: Result<Vec<EpisodeRow>> = (|| {
            let policy = load_any(d, &expect, &device, task.as_ref())?;
            let mut timing = Timing::default();
            let mut rows = Vec::new();
            for batch in seeds.chunks(100) {
                let mut start = Start::new(policy.name(), batch, &setup)?;
                start.observe.clone_from(&observe);
                rows.extend(pool.install(|| sim_branch(policy.as_ref(), start, &setup, &mut timing))?.rows);
                pb.inc(batch.len() as u64);
            }
            Ok(rows)
        })();
        match rows {
            Ok(rows) => {
                append_rows(&jsonl, &rows)?;
                let refs: Vec<&EpisodeRow> = rows.iter().collect();
                let stats = branch_stats(&refs, 2000, 0);
                say!(
                    say,
                    "{name:<16} mean score {:.3}  success {:.1}%  ({:.0} s)",
                    stats.mean,
                    100.0 * stats.success_rate,
                    started.elapsed().as_secs_f64()
                );
                if args.record_scores {
                    record(d, &stats, c.seed_start, c.episodes, max_steps, inv)?;
                }
                summary.push(json!({"name": name, "mujoco": stats}));
            }
            Err(e) => {
                tracing::error!("{name}: {e:#}; continuing with the other checkpoints");
                summary.push(json!({"name": name, "error": format!("{e:#}")}));
                ok = false;
            }
        }
    }
    pb.finish_and_clear();
    // The episodes ran on the pool's threads: what they hold for the task goes before
    // the pool does (`Task::release_thread`).
    pool.broadcast(|_| task.release_thread());
    write_json(
        &out.file("summary.json"),
        &json!({"scenario": c.scenario, "policies_dir": dir, "seed_start": c.seed_start, "episodes": c.episodes,
                "max_steps": max_steps, "score": task.score_kind().describe(),
                "observe_through": args.observe_through.as_ref().map(|p| p.display().to_string()),
                "seed": args.seed.unwrap_or(0),
                "policies": summary}),
    )?;
    let o = out.commit()?;
    say!(say, "-> {}", o.display());
    Ok(ok)
}

/// The hook that shows the policy each frame as the world model at `dir` (loaded on
/// `device`) encodes and decodes it (no dynamics).
fn through_autoencoder(dir: &std::path::Path, size: usize, device: &burn::tensor::Device) -> Result<Observe> {
    let wm = WorldModel::load(dir, device).with_context(|| format!("--observe-through {}", dir.display()))?;
    let side = wm.image_size();
    if side != size {
        refuse!(
            "--observe-through {}: the model renders {side}x{side} frames, the task's are {size}x{size}",
            dir.display()
        );
    }
    Ok(Arc::new(move |frames: &mut [Vec<u8>]| {
        let refs: Vec<&[u8]> = frames.iter().map(Vec::as_slice).collect();
        let z = wm.encode(frames_to_tensor(&refs, size, wm.device())); // [b, C, s, s]
        let rendered = tensor_to_frames(wm.decode(z)); // b frames of size x size x 3
        for (f, r) in frames.iter_mut().zip(rendered) {
            *f = r;
        }
    }))
}

/// Writes `provenance.json` into a checkpoint: its training provenance plus the measured score.
fn record(
    dir: &std::path::Path,
    stats: &harness::results::BranchStats,
    seed_start: u64,
    episodes: u64,
    max_steps: usize,
    inv: &Invocation,
) -> Result<()> {
    let made = policies::dir::read_made(dir)?;
    let args: Vec<String> = inv.command_line.clone();
    let scores = PolicyScores {
        epoch: made.epoch,
        mujoco_score: MujocoScore {
            ci95: stats.ci95,
            commit: inv.commit.clone(),
            max_steps,
            mean: stats.mean,
            measured_with: args.join(" "),
            seeds: [seed_start, seed_start + episodes - 1],
            success_ci95: stats.success_ci95,
            success_rate: stats.success_rate,
        },
        step: made.step,
        train_loss: made.train_loss,
        training: made.provenance,
        other: Default::default(),
    };
    Ok(write_json(&dir.join("provenance.json"), &scores)?)
}
