//! `evalharness simulate --scenario lift|can`: a scripted behaviour in one of
//! robosuite's tasks (any [`ArmTask`]), simulated in MuJoCo.
//!
//! Writes into `--out` (staged, so an interrupted run leaves only `OUT.partial`):
//! - `config.json`: the resolved scenario and arguments;
//! - `episodes.jsonl`: one line per control step (seed, step, the state row
//!   before the action, the 7-D action, success after it);
//! - `initial_states.jsonl`: each episode's drawn initial state (object size and
//!   pose, arm joints), so that another simulator can start from it;
//! - `summary.json`: success rate and per-episode results;
//! - a GIF of the first episode's agentview frames.
//!
//! Episodes run on `--jobs` threads in batches and come back in seed order, so
//! any `--jobs` gives byte-identical files.

use std::io::{BufWriter, Write};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use scenarios::robosuite::rollout::{ArmTask, Perturbation};
use scenarios::robosuite::runs::{ArmRun, behaviour};
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
struct InitLine<'a, I: Serialize> {
    seed: u64,
    #[serde(flatten)]
    init: &'a I,
}

/// One episode's entry in `summary.json`.
#[derive(Serialize)]
struct EpisodeSummary {
    seed: u64,
    success: bool,
    steps: usize,
    /// Control steps until the first success (none for a failure).
    steps_to_success: Option<usize>,
}

/// Writes `config.json`: the resolved scenario and arguments of the run.
fn write_config<T: ArmTask>(out: &Staged, args: &SimulateArgs, task: &T, max_steps: usize) -> Result<()> {
    let c = &args.common;
    write_json(
        &out.file("config.json"),
        &json!({
            "command": "simulate",
            "scenario": task.name(),
            "scenario_config": task.config_json(),
            "policy": args.policy,
            "episodes": c.episodes,
            "seed_start": c.seed_start,
            "max_steps": max_steps,
            "stop_at_success": !args.no_early_stop,
            "noise": c.noise,
            "lag": c.lag,
            "state_columns": task.state_columns(),
            "evalharness_version": env!("CARGO_PKG_VERSION"),
        }),
    )?;
    Ok(())
}

/// Runs the command.
pub fn run<T: ArmTask>(args: &SimulateArgs, task: &T, quiet: bool) -> Result<ExitCode> {
    let c = &args.common;
    let name = task.name();
    let kind = behaviour(task, &args.policy)?;
    if !(16..=1024).contains(&args.gif_size) {
        bail!("--gif-size must be in 16..=1024, got {}", args.gif_size);
    }
    let max_steps = c.max_steps.map_or(task.max_steps(), |m| m as usize);
    let perturbation = Perturbation { noise: c.noise, lag: c.lag };
    let work: Vec<(u64, T::Behaviour)> =
        harness::seed::range(c.seed_start, c.episodes)?.map(|seed| (seed, kind)).collect();
    let out = Staged::new(&args.out, c.force, &args.inputs())?;
    write_config(&out, args, task, max_steps)?;
    let open = |name: &str| -> Result<(std::path::PathBuf, BufWriter<std::fs::File>)> {
        let p = out.file(name);
        let f = std::fs::File::create(&p).with_context(|| format!("creating {}", p.display()))?;
        Ok((p, BufWriter::new(f)))
    };
    let (jsonl_path, mut jsonl) = open("episodes.jsonl")?;
    let (init_path, mut inits) = open("initial_states.jsonl")?;
    let pb = progress::bar(c.episodes, &format!("simulate {name}"), quiet);
    let mut per_episode = Vec::new();
    let gif_size = args.gif_size;
    let runner = ArmRun { task, perturbation, max_steps, stop_at_success: !args.no_early_stop, jobs: c.jobs };
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
            let init = InitLine { seed: ep.seed, init: &ep.init };
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
            per_episode.push(EpisodeSummary {
                seed: ep.seed,
                success: ep.success,
                steps: ep.rows.len(),
                steps_to_success: first,
            });
            pb.inc(1);
            anyhow::Ok(())
        },
    )?;
    pb.finish_and_clear();
    jsonl.flush().with_context(|| format!("writing {}", jsonl_path.display()))?;
    inits.flush().with_context(|| format!("writing {}", init_path.display()))?;
    let n = per_episode.len().max(1) as f64;
    let success_rate = per_episode.iter().filter(|e| e.success).count() as f64 / n;
    write_json(
        &out.file("summary.json"),
        &json!({
            "scenario": name,
            "policy": args.policy,
            "episodes": per_episode.len(),
            "success_rate": success_rate,
            "per_episode": per_episode,
        }),
    )?;
    let dir = out.commit()?;
    outln!(
        "{name} {}: {} episodes, success rate {:.1}% -> {}",
        args.policy,
        c.episodes,
        100.0 * success_rate,
        dir.display()
    );
    Ok(ExitCode::SUCCESS)
}
