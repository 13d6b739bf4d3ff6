//! `evalharness simulate`: run a behaviour in the MuJoCo reference simulator.
//!
//! Writes `summary.json`, `episodes.jsonl` (one line per control step),
//! `config.json` (the resolved scenario and arguments) and a GIF of the first
//! episode into `--out`, staged so that an interrupted run leaves only `OUT.partial`.

use std::io::{BufWriter, Write};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use serde_json::json;

use crate::cli::RendererKind;
use crate::cli::SimulateArgs;
use crate::output::{Staged, write_json};
use crate::progress;
use scenarios::pusht::runs::{BehaviourKind, FrameSpec, Perturbation};

/// Mean absolute difference between the left (MuJoCo) and right (raster) halves.
fn side_by_side_difference(frames: &[Vec<u8>], size: usize) -> f64 {
    let row = size * 3;
    let mut sum = 0.0;
    let mut n = 0usize;
    for f in frames {
        for r in f.chunks_exact(2 * row) {
            let (a, b) = r.split_at(row);
            sum += a.iter().zip(b).map(|(x, y)| f64::from(x.abs_diff(*y))).sum::<f64>();
            n += row;
        }
    }
    sum / n.max(1) as f64
}

/// One episode's entry in `summary.json`.
#[derive(serde::Serialize)]
struct EpisodeSummary {
    seed: u64,
    score: f64,
    success: bool,
    steps: usize,
}

/// Writes `summary.json` (and `render_crosscheck.json` when MuJoCo's frames were drawn beside
/// the rasteriser's, for the first episode: its frame side and seed); returns the mean score
/// and the success rate.
fn write_summaries(
    out: &Staged,
    kind: BehaviourKind,
    per_episode: Vec<EpisodeSummary>,
    crosscheck: Option<f64>,
    (gif_size, first_seed): (usize, u64),
) -> Result<(f64, f64)> {
    let n = per_episode.len().max(1) as f64;
    let mean_score = per_episode.iter().map(|e| e.score).sum::<f64>() / n;
    let success_rate = per_episode.iter().filter(|e| e.success).count() as f64 / n;
    write_json(
        &out.file("summary.json"),
        &json!({
            "scenario": "pusht",
            "policy": kind.name(),
            "episodes": per_episode.len(),
            "mean_score": mean_score,
            "success_rate": success_rate,
            "per_episode": per_episode,
        }),
    )?;
    if let Some(mad) = crosscheck {
        write_json(
            &out.file("render_crosscheck.json"),
            &json!({
                "what": "mean absolute difference per channel (0-255) between MuJoCo's renderer and \
                         the rasteriser over the first episode's frames",
                "size": gif_size,
                "episode_seed": first_seed,
                "mean_abs_diff": mad,
            }),
        )?;
    }
    Ok((mean_score, success_rate))
}

/// Runs the command.
pub fn run(args: &SimulateArgs, quiet: bool) -> Result<ExitCode> {
    let path = std::path::Path::new(&args.policy);
    if path.is_dir() {
        if let Some(wm) = &args.replay_imagined {
            return super::simulate_replay::run(args, wm, quiet);
        }
        return super::simulate_policy::run(args, quiet);
    }
    if let Some(seed) = args.seed {
        bail!(
            "--seed {seed}: it seeds a policy checkpoint's sampling noise; --policy {} is a built-in behaviour",
            args.policy
        );
    }
    if let Some(wm) = &args.replay_imagined {
        bail!(
            "--replay-imagined {}: only a policy checkpoint acts on imagined frames; --policy {} is not a checkpoint folder",
            wm.display(),
            args.policy
        );
    }
    if let Some(wm) = &args.observe_through {
        bail!(
            "--observe-through {}: only a policy checkpoint sees frames; --policy {} is a built-in behaviour",
            wm.display(),
            args.policy
        );
    }
    // Behaviour names have no path separator: one that does meant a checkpoint folder.
    if args.policy.contains(std::path::MAIN_SEPARATOR) {
        bail!(
            "--policy {}: no such checkpoint folder (a folder, or a built-in behaviour's name)",
            path.display()
        );
    }
    let c = &args.common;
    let cfg =
        match scenarios::scenario(&c.scenario).with_context(|| format!("loading scenario {}", c.scenario))? {
            scenarios::Scenario::Lift(cfg) => {
                let task = scenarios::lift::LiftSim::new(cfg).context("setting up Lift")?;
                return super::simulate_arm::run(args, &task, quiet);
            }
            scenarios::Scenario::Can(cfg) => {
                let task = scenarios::can::CanSim::new(cfg).context("setting up Can")?;
                return super::simulate_arm::run(args, &task, quiet);
            }
            scenarios::Scenario::PushT(cfg) => *cfg,
        };
    run_pusht(args, cfg, quiet)
}

/// A Push-T scripted behaviour `args` names, simulated with the scenario `cfg`.
fn run_pusht(args: &SimulateArgs, cfg: scenarios::pusht::PushTConfig, quiet: bool) -> Result<ExitCode> {
    let c = &args.common;
    super::collect::refuse_run_on_for_pusht(args.no_early_stop)?;
    let kind = BehaviourKind::parse(&args.policy)?;
    if !(16..=1024).contains(&args.gif_size) {
        anyhow::bail!("--gif-size must be in 16..=1024, got {}", args.gif_size);
    }
    let runner =
        super::collect::pusht_runner(cfg, c.jobs, c.max_steps, Perturbation { noise: c.noise, lag: c.lag })?;
    let work: Vec<(u64, BehaviourKind)> =
        harness::seed::range(c.seed_start, c.episodes)?.map(|seed| (seed, kind)).collect();
    let out = Staged::new(&args.out, c.force, &args.inputs())?;
    write_json(
        &out.file("config.json"),
        &json!({
            "command": "simulate",
            "scenario": runner.cfg,
            "policy": kind.name(),
            "episodes": c.episodes,
            "seed_start": c.seed_start,
            "max_steps": runner.max_steps,
            "noise": c.noise,
            "lag": c.lag,
            "renderer": args.renderer,
            "evalharness_version": env!("CARGO_PKG_VERSION"),
        }),
    )?;
    let jsonl_path = out.file("episodes.jsonl");
    let mut jsonl = BufWriter::new(
        std::fs::File::create(&jsonl_path).with_context(|| format!("creating {}", jsonl_path.display()))?,
    );
    let pb = progress::bar(c.episodes, "simulate", quiet);
    let mut per_episode = Vec::new();
    let mut crosscheck = None;
    let gif_size = args.gif_size;
    runner.run(
        &work,
        |i| {
            (i == 0)
                .then_some(FrameSpec { size: gif_size, beside_mujoco: args.renderer == RendererKind::Mujoco })
        },
        |i, ep| {
            for r in &ep.rows {
                let line = json!({
                    "seed": ep.seed,
                    "step": r.step,
                    "agent": r.agent,
                    "block": r.block.to_array(),
                    "goal": ep.goal.to_array(),
                    "action": r.action,
                    "coverage": r.coverage,
                });
                writeln!(jsonl, "{line}").with_context(|| format!("writing {}", jsonl_path.display()))?;
            }
            if i == 0 {
                let h = u16::try_from(gif_size).unwrap_or(u16::MAX);
                let w = if args.renderer == RendererKind::Mujoco { 2 * h } else { h };
                let gif = out.file(&format!("episode_{}.gif", ep.seed));
                reports::gif::write_gif(&gif, &ep.frames, w, h, 100)?;
                if args.renderer == RendererKind::Mujoco {
                    crosscheck = Some(side_by_side_difference(&ep.frames, gif_size));
                }
            }
            per_episode.push(EpisodeSummary {
                seed: ep.seed,
                score: ep.score,
                success: ep.success,
                steps: ep.rows.len(),
            });
            pb.inc(1);
            anyhow::Ok(())
        },
    )?;
    pb.finish_and_clear();
    jsonl.flush().with_context(|| format!("writing {}", jsonl_path.display()))?;
    let (mean_score, success_rate) =
        write_summaries(&out, kind, per_episode, crosscheck, (gif_size, c.seed_start))?;
    let dir = out.commit()?;
    outln!(
        "pusht {}: {} episodes, mean score {:.3}, success rate {:.1}% -> {}",
        kind.name(),
        c.episodes,
        mean_score,
        100.0 * success_rate,
        dir.display()
    );
    Ok(ExitCode::SUCCESS)
}
