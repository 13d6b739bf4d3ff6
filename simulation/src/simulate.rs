//! `evalharness simulate`: a task's scripted behaviour in the MuJoCo reference simulator
//! (a policy checkpoint folder goes to [`super::simulate_policy`] or, with
//! `--replay-imagined`, [`super::simulate_replay`]).
//!
//! Writes into `--out`, staged so that an interrupted run leaves only `OUT.partial`:
//! - `config.json`: the resolved scenario and arguments ([`RunConfig`]);
//! - `episodes.jsonl`: one line per control step, in the task's own columns;
//! - `initial_states.jsonl`: each episode's drawn initial state, for tasks whose initial
//!   state another simulator can start from (Lift, Can);
//! - `summary.json`: the score, success and steps of every episode ([`Summary`]);
//! - a GIF of the first episode, and with `--renderer mujoco` (tasks with a renderer of
//!   their own beside MuJoCo's: Push-T) `render_crosscheck.json`.
//!
//! Episodes run on `--jobs` threads and come back in seed order, so any `--jobs` gives
//! byte-identical files.

use std::io::{BufWriter, Write};
use std::path::Path;

use crate::error::{Context, Result, SimError, refuse};
use crate::{Invocation, say};
use harness::scripted::{FrameRequest, Settings};
use harness::task::{ScoreKind, Task};
use serde::Serialize;

use crate::args::{RendererKind, SimulateArgs};
use crate::collect::{behaviour_index, load_task, refuse_no_early_stop, scripted_of, settings};
use runner::command::write_json;
use runner::output::Staged;

/// `config.json`: the resolved scenario and arguments of the run. The fields of this
/// module's files are declared alphabetically: the key order they had as sorted maps.
#[derive(Serialize)]
struct RunConfig<'a> {
    command: &'static str,
    episodes: u64,
    evalharness_version: &'static str,
    lag: usize,
    max_steps: usize,
    noise: f64,
    policy: &'a str,
    renderer: RendererKind,
    scenario: &'a str,
    scenario_config: serde_json::Value,
    seed_start: u64,
    state_columns: Vec<String>,
    stop_at_success: bool,
}

/// One episode's entry in `summary.json`.
#[derive(Serialize)]
struct EpisodeSummary {
    score: f64,
    seed: u64,
    steps: usize,
    /// Control steps until the first success (none for a failure).
    steps_to_success: Option<usize>,
    success: bool,
}

/// `summary.json`.
#[derive(Serialize)]
struct Summary<'a> {
    episodes: usize,
    mean_score: f64,
    per_episode: Vec<EpisodeSummary>,
    policy: &'a str,
    scenario: &'a str,
    success_rate: f64,
}

/// `render_crosscheck.json`: MuJoCo's frames against the task's own renderer's.
#[derive(Serialize)]
struct Crosscheck {
    episode_seed: u64,
    mean_abs_diff: f64,
    size: usize,
    what: &'static str,
}

/// Mean absolute difference between the left (MuJoCo) and right (the task's own) halves.
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

/// Refuses the flags that only a policy checkpoint takes, naming them.
fn refuse_checkpoint_flags(args: &SimulateArgs) -> Result<()> {
    let policy = &args.policy;
    if let Some(seed) = args.seed {
        refuse!(
            "--seed {seed}: it seeds a policy checkpoint's sampling noise; --policy {policy} is a built-in behaviour"
        );
    }
    if let Some(wm) = &args.replay_imagined {
        refuse!(
            "--replay-imagined {}: only a policy checkpoint acts on imagined frames; --policy {policy} is not a \
             checkpoint folder",
            wm.display()
        );
    }
    if let Some(wm) = &args.observe_through {
        refuse!(
            "--observe-through {}: only a policy checkpoint sees frames; --policy {policy} is a built-in behaviour",
            wm.display()
        );
    }
    // Behaviour names have no path separator: one that does meant a checkpoint folder.
    if policy.contains(std::path::MAIN_SEPARATOR) {
        refuse!("--policy {policy}: no such checkpoint folder (a folder, or a built-in behaviour's name)");
    }
    Ok(())
}

/// Runs the command.
pub fn run(args: &SimulateArgs, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<bool> {
    if Path::new(&args.policy).is_dir() {
        if let Some(wm) = &args.replay_imagined {
            return crate::simulate_replay::run(args, wm, inv, say);
        }
        return crate::simulate_policy::run(args, inv, say);
    }
    refuse_checkpoint_flags(args)?;
    let task = load_task(&args.common.scenario)?;
    run_scripted(args, task.as_ref(), inv, say)
}

/// The scripted behaviour `args` names, simulated in `task`.
fn run_scripted(
    args: &SimulateArgs,
    task: &dyn Task,
    inv: &Invocation,
    say: &mut dyn FnMut(&str),
) -> Result<bool> {
    let c = &args.common;
    let scripted = scripted_of(task)?;
    refuse_no_early_stop(task, args.no_early_stop)?;
    let kind = behaviour_index(task, &args.policy, "; or a checkpoint folder")?;
    let beside = args.renderer == RendererKind::Mujoco;
    if beside && !scripted.second_renderer() {
        refuse!(
            "--renderer mujoco: the {} task's frames are MuJoCo's already (no second renderer)",
            task.name()
        );
    }
    let settings = settings(c, task, args.no_early_stop);
    let work: Vec<(u64, usize)> =
        harness::seed::range(c.seed_start, c.episodes)?.map(|seed| (seed, kind)).collect();
    let out = Staged::new(&args.out, c.force, &args.inputs())?;
    let config = run_config(args, task, scripted, &settings);
    write_json(&out.file("config.json"), &config)?;
    let open = |name: &str| -> Result<(std::path::PathBuf, BufWriter<std::fs::File>)> {
        let p = out.file(name);
        let f = std::fs::File::create(&p).with_context(|| format!("creating {}", p.display()))?;
        Ok((p, BufWriter::new(f)))
    };
    let (jsonl_path, mut jsonl) = open("episodes.jsonl")?;
    let mut inits: Option<(std::path::PathBuf, BufWriter<std::fs::File>)> = None;
    let pb = runner::progress::bar(c.episodes, &format!("simulate {}", task.name()), inv.quiet);
    let mut per_episode = Vec::new();
    let mut crosscheck = None;
    let gif_size = args.gif_size;
    let frames = |i| (i == 0).then_some(FrameRequest { size: gif_size, beside_reference: beside });
    let gif_delay_ms = (1000.0 / task.control_hz()).round() as u32;
    let mut done = |i: usize, ep: harness::scripted::ScriptedEpisode| -> Result<()> {
        for line in &ep.step_lines {
            writeln!(jsonl, "{line}").with_context(|| format!("writing {}", jsonl_path.display()))?;
        }
        if let Some(line) = &ep.initial_state {
            if inits.is_none() {
                inits = Some(open("initial_states.jsonl")?);
            }
            if let Some((path, w)) = inits.as_mut() {
                writeln!(w, "{line}").with_context(|| format!("writing {}", path.display()))?;
            }
        }
        if i == 0 {
            let h = u16::try_from(gif_size).unwrap_or(u16::MAX);
            let w = if beside { 2 * h } else { h };
            let gif = out.file(&format!("episode_{}.gif", ep.seed));
            reports::gif::write_gif(&gif, &ep.frames, w, h, gif_delay_ms)?;
            crosscheck = beside.then(|| side_by_side_difference(&ep.frames, gif_size));
        }
        per_episode.push(EpisodeSummary {
            seed: ep.seed,
            score: ep.score,
            success: ep.success,
            steps: ep.steps,
            steps_to_success: ep.steps_to_success,
        });
        pb.inc(1);
        Ok(())
    };
    scripted
        .run(&work, &settings, &frames, &mut |i, ep| done(i, ep).map_err(SimError::into_task))
        .map_err(SimError::from_task)?;
    pb.finish_and_clear();
    jsonl.flush().with_context(|| format!("writing {}", jsonl_path.display()))?;
    if let Some((path, mut w)) = inits {
        w.flush().with_context(|| format!("writing {}", path.display()))?;
    }
    finish(out, (args, task), per_episode, crosscheck, say)?;
    Ok(true)
}

/// `config.json` of a run of `args` in `task`.
fn run_config<'a>(
    args: &'a SimulateArgs,
    task: &'a dyn Task,
    scripted: &dyn harness::scripted::Scripted,
    settings: &Settings,
) -> RunConfig<'a> {
    let c = &args.common;
    RunConfig {
        command: "simulate",
        scenario: task.name(),
        scenario_config: scripted.config_json(),
        policy: &args.policy,
        episodes: c.episodes,
        seed_start: c.seed_start,
        max_steps: settings.max_steps,
        stop_at_success: settings.stop_at_success,
        noise: c.noise,
        lag: c.lag,
        renderer: args.renderer,
        state_columns: scripted.state_columns(),
        evalharness_version: env!("CARGO_PKG_VERSION"),
    }
}

/// Writes `summary.json` (and `render_crosscheck.json` when MuJoCo's frames were drawn
/// beside the task's own), commits the run and says its result.
fn finish(
    out: Staged,
    (args, task): (&SimulateArgs, &dyn Task),
    per_episode: Vec<EpisodeSummary>,
    crosscheck: Option<f64>,
    say: &mut dyn FnMut(&str),
) -> Result<()> {
    let c = &args.common;
    let n = per_episode.len().max(1) as f64;
    let mean_score = per_episode.iter().map(|e| e.score).sum::<f64>() / n;
    let success_rate = per_episode.iter().filter(|e| e.success).count() as f64 / n;
    let summary = Summary {
        scenario: task.name(),
        policy: &args.policy,
        episodes: per_episode.len(),
        mean_score,
        success_rate,
        per_episode,
    };
    write_json(&out.file("summary.json"), &summary)?;
    if let Some(mean_abs_diff) = crosscheck {
        let what = "mean absolute difference per channel (0-255) between MuJoCo's renderer and the task's own \
                    renderer over the first episode's frames";
        let check = Crosscheck { what, size: args.gif_size, episode_seed: c.seed_start, mean_abs_diff };
        write_json(&out.file("render_crosscheck.json"), &check)?;
    }
    let dir = out.commit()?;
    // A task scored by success alone has no mean score apart from its success rate.
    let score = if task.score_kind() == ScoreKind::Success {
        String::new()
    } else {
        format!(", mean score {mean_score:.3}")
    };
    say!(
        say,
        "{} {}: {} episodes{score}, success rate {:.1}% -> {}",
        task.name(),
        args.policy,
        c.episodes,
        100.0 * success_rate,
        dir.display()
    );
    Ok(())
}
