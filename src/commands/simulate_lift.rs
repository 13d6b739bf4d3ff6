//! `evalharness simulate --scenario lift`: a scripted behaviour in robosuite's
//! Lift, simulated in MuJoCo.
//!
//! Writes into `--out` (staged, so an interrupted run leaves only `OUT.partial`):
//! - `config.json`: the resolved scenario and arguments;
//! - `episodes.jsonl`: one line per control step (seed, step, the state row
//!   before the action, the 7-D action, success after it);
//! - `initial_states.jsonl`: each episode's drawn initial state (cube size and
//!   pose, arm joints), so that another simulator can start from it;
//! - `summary.json`: success rate and per-episode results;
//! - a GIF of the first episode's agentview frames.
//!
//! Episodes run on `--jobs` threads in batches and come back in seed order, so
//! any `--jobs` gives byte-identical files.

use std::io::{BufWriter, Write};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use rayon::prelude::*;
use scenarios::lift::{
    LiftBehaviour, LiftConfig, LiftEpisodeRecord, LiftPerturbation, LiftSim, STATE_COLUMNS, run_lift_episode,
};
use serde::Serialize;
use serde_json::json;

use crate::cli::SimulateArgs;
use crate::output::{Staged, write_json};
use crate::progress;

/// One line of `episodes.jsonl`.
#[derive(Serialize)]
struct StepLine<'a> {
    seed: u64,
    step: u32,
    state: &'a [f64],
    action: [f64; 7],
    success: bool,
}

/// One line of `initial_states.jsonl`.
#[derive(Serialize)]
struct InitLine {
    seed: u64,
    cube_half: [f64; 3],
    cube_pos: [f64; 3],
    cube_quat: [f64; 4],
    arm_q: [f64; 7],
}

/// Parses `--policy` for Lift.
pub fn behaviour(name: &str) -> Result<LiftBehaviour> {
    LiftBehaviour::parse(name).with_context(|| {
        let names: Vec<&str> = LiftBehaviour::ALL.iter().map(|(n, _)| *n).collect();
        format!("unknown Lift behaviour '{name}' (built-in: {})", names.join(", "))
    })
}

/// How a batch of Lift episodes runs.
pub struct LiftRun<'a> {
    /// The simulator.
    pub sim: &'a LiftSim,
    /// Noise and lag on the behaviours' actions.
    pub perturbation: LiftPerturbation,
    /// Step limit per episode.
    pub max_steps: usize,
    /// End an episode at its first success.
    pub stop_at_success: bool,
    /// Worker threads.
    pub jobs: usize,
}

impl LiftRun<'_> {
    /// Runs `work` on the worker threads in batches, handing the episodes to
    /// `done` in order; `frames(i)` asks episode `i` for frames of that side.
    pub fn run(
        &self,
        work: &[(u64, LiftBehaviour)],
        frames: impl Fn(usize) -> Option<usize> + Sync,
        mut done: impl FnMut(usize, LiftEpisodeRecord) -> Result<()>,
    ) -> Result<()> {
        let jobs = self.jobs.max(1);
        let pool = rayon::ThreadPoolBuilder::new().num_threads(jobs).build()?;
        let batch = jobs * 4;
        for (b, chunk) in work.chunks(batch).enumerate() {
            let results: Vec<Result<LiftEpisodeRecord>> = pool.install(|| {
                chunk
                    .par_iter()
                    .enumerate()
                    .map(|(k, &(seed, kind))| {
                        let size = frames(b * batch + k);
                        run_lift_episode(
                            self.sim,
                            kind,
                            self.perturbation,
                            seed,
                            self.max_steps,
                            self.stop_at_success,
                            size,
                        )
                        .with_context(|| format!("Lift episode seed {seed} ({})", kind.name()))
                    })
                    .collect()
            });
            for (k, r) in results.into_iter().enumerate() {
                done(b * batch + k, r?)?;
            }
        }
        Ok(())
    }
}

/// Runs the command.
pub fn run(args: &SimulateArgs, cfg: LiftConfig, quiet: bool) -> Result<ExitCode> {
    let c = &args.common;
    let kind = behaviour(&args.policy)?;
    if !(16..=1024).contains(&args.gif_size) {
        bail!("--gif-size must be in 16..=1024, got {}", args.gif_size);
    }
    if !(c.noise.is_finite() && c.noise >= 0.0) {
        bail!("--noise must be a finite std >= 0, got {}", c.noise);
    }
    let sim = LiftSim::new(cfg.clone()).context("setting up Lift")?;
    let max_steps = c.max_steps.map_or(cfg.max_steps, |m| m as usize);
    let perturbation = LiftPerturbation { noise: c.noise, lag: c.lag };
    let work: Vec<(u64, LiftBehaviour)> =
        harness::seed::range(c.seed_start, c.episodes)?.map(|seed| (seed, kind)).collect();
    let out = Staged::new(&args.out, c.force)?;
    write_json(
        &out.file("config.json"),
        &json!({
            "command": "simulate",
            "scenario": "lift",
            "lift": cfg,
            "policy": kind.name(),
            "episodes": c.episodes,
            "seed_start": c.seed_start,
            "max_steps": max_steps,
            "stop_at_success": !args.no_early_stop,
            "noise": c.noise,
            "lag": c.lag,
            "state_columns": STATE_COLUMNS,
            "evalharness_version": env!("CARGO_PKG_VERSION"),
        }),
    )?;
    let open = |name: &str| -> Result<(std::path::PathBuf, BufWriter<std::fs::File>)> {
        let p = out.file(name);
        let f = std::fs::File::create(&p).with_context(|| format!("creating {}", p.display()))?;
        Ok((p, BufWriter::new(f)))
    };
    let (jsonl_path, mut jsonl) = open("episodes.jsonl")?;
    let (init_path, mut inits) = open("initial_states.jsonl")?;
    let pb = progress::bar(c.episodes, "simulate lift", quiet);
    let mut per_episode = Vec::new();
    let gif_size = args.gif_size;
    let runner =
        LiftRun { sim: &sim, perturbation, max_steps, stop_at_success: !args.no_early_stop, jobs: c.jobs };
    runner.run(
        &work,
        |i| (i == 0).then_some(gif_size),
        |i, ep| {
            for r in &ep.rows {
                let line = StepLine {
                    seed: ep.seed,
                    step: r.step,
                    state: &r.state,
                    action: r.action,
                    success: r.success,
                };
                serde_json::to_writer(&mut jsonl, &line)?;
                writeln!(jsonl).with_context(|| format!("writing {}", jsonl_path.display()))?;
            }
            let init = InitLine {
                seed: ep.seed,
                cube_half: ep.init.cube_half,
                cube_pos: ep.init.cube_pos,
                cube_quat: ep.init.cube_quat,
                arm_q: ep.init.arm_q,
            };
            serde_json::to_writer(&mut inits, &init)?;
            writeln!(inits).with_context(|| format!("writing {}", init_path.display()))?;
            if i == 0 {
                let side = u16::try_from(gif_size).unwrap_or(u16::MAX);
                reports::gif::write_gif(
                    &out.file(&format!("episode_{}.gif", ep.seed)),
                    &ep.frames,
                    side,
                    side,
                    50,
                )?;
            }
            let first = ep.rows.iter().position(|r| r.success).map(|s| s + 1);
            per_episode.push(json!({
                "seed": ep.seed,
                "success": ep.success,
                "steps": ep.rows.len(),
                "steps_to_success": first,
            }));
            pb.inc(1);
            Ok(())
        },
    )?;
    pb.finish_and_clear();
    jsonl.flush().with_context(|| format!("writing {}", jsonl_path.display()))?;
    inits.flush().with_context(|| format!("writing {}", init_path.display()))?;
    let n = per_episode.len().max(1) as f64;
    let success_rate = per_episode.iter().filter(|e| e["success"] == true).count() as f64 / n;
    write_json(
        &out.file("summary.json"),
        &json!({
            "scenario": "lift",
            "policy": kind.name(),
            "episodes": per_episode.len(),
            "success_rate": success_rate,
            "per_episode": per_episode,
        }),
    )?;
    let dir = out.commit()?;
    println!(
        "lift {}: {} episodes, success rate {:.1}% -> {}",
        kind.name(),
        c.episodes,
        100.0 * success_rate,
        dir.display()
    );
    Ok(ExitCode::SUCCESS)
}
