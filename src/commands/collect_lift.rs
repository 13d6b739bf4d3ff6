//! `evalharness collect --scenario lift`: a Lift dataset in the replay-buffer
//! zarr layout, from a seeded mix of scripted behaviours.
//!
//! The layout is Push-T's with Lift's sizes:
//! - `data/img`: the agentview image before each action, `size`² RGB (96 by
//!   default, the paper's size for simulated tasks);
//! - `data/action`: robomimic's 7-D OSC_POSE actions;
//! - `data/state`: the 23 columns of [`scenarios::lift::STATE_COLUMNS`] (cube
//!   pose, grip-site pose, fingers, arm joints);
//! - `data/success`: 1 once the cube is lifted, after each action.
//!
//! Each episode's behaviour is drawn from `--mix` with a random number derived
//! from its seed, so the dataset is a pure function of the arguments, whatever
//! `--jobs` is.

use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use harness::replay::{EpisodeArrays, ReplaySpec, ReplayWriter};
use scenarios::lift::{
    LiftBehaviour, LiftConfig, LiftEpisodeRecord, LiftPerturbation, LiftSim, STATE_COLUMNS,
};
use serde_json::json;

use super::collect::{draw, parse_mix_with};
use super::simulate_lift::{LiftRun, behaviour};
use crate::cli::CollectArgs;
use crate::progress;

/// Lift's default `--mix`: half expert episodes, half the ways weak policies fail.
pub const LIFT_MIX: &str = "expert=0.5,miss=0.1,drop=0.1,push=0.1,hesitate=0.1,random=0.1";

/// Side of the stored images.
const IMAGE_SIZE: usize = 96;

/// One episode's arrays: the frame before each action, its state row, the
/// action and success after it.
fn episode_arrays(ep: &LiftEpisodeRecord) -> EpisodeArrays {
    let mut arrays = EpisodeArrays::default();
    for f in &ep.frames[..ep.rows.len()] {
        arrays.img.extend_from_slice(f);
    }
    let mut success = Vec::with_capacity(ep.rows.len());
    for r in &ep.rows {
        arrays.action.extend(r.action.map(|v| v as f32));
        arrays.state.extend(r.state.iter().map(|&v| v as f32));
        success.push(if r.success { 1.0 } else { 0.0 });
    }
    arrays.extras.push(success);
    arrays
}

/// Runs the command.
pub fn run(args: &CollectArgs, cfg: LiftConfig, quiet: bool) -> Result<ExitCode> {
    let c = &args.common;
    if !(c.noise.is_finite() && c.noise >= 0.0) {
        bail!("--noise must be a finite std >= 0, got {}", c.noise);
    }
    let mix_text = args.mix.as_deref().unwrap_or(LIFT_MIX);
    let mix = parse_mix_with(mix_text, behaviour)?;
    let sim = LiftSim::new(cfg.clone()).context("setting up Lift")?;
    let max_steps = c.max_steps.map_or(cfg.max_steps, |m| m as usize);
    let perturbation = LiftPerturbation { noise: c.noise, lag: c.lag };
    let work: Vec<(u64, LiftBehaviour)> =
        harness::seed::range(c.seed_start, c.episodes)?.map(|seed| (seed, draw(&mix, seed))).collect();
    let spec = ReplaySpec {
        image_hw: [IMAGE_SIZE, IMAGE_SIZE],
        action_dim: 7,
        state_dim: STATE_COLUMNS.len(),
        extras: vec!["success".into()],
    };
    let mut writer = ReplayWriter::create(&args.out, spec, c.force)?;
    let pb = progress::bar(c.episodes, "collect lift", quiet);
    let mut episodes = Vec::new();
    let runner = LiftRun { sim: &sim, perturbation, max_steps, stop_at_success: true, jobs: c.jobs };
    runner.run(
        &work,
        |_| Some(IMAGE_SIZE),
        |_, ep| {
            writer.append(&episode_arrays(&ep))?;
            episodes.push(json!({
                "seed": ep.seed,
                "behaviour": ep.behaviour.name(),
                "steps": ep.rows.len(),
                "success": ep.success,
            }));
            pb.inc(1);
            Ok(())
        },
    )?;
    pb.finish_and_clear();
    let n = episodes.len();
    let steps: u64 = episodes.iter().filter_map(|e| e["steps"].as_u64()).sum();
    let attrs = json!({ "evalharness": {
        "version": env!("CARGO_PKG_VERSION"),
        "scenario": "lift",
        "scenario_config": cfg,
        "state_columns": STATE_COLUMNS,
        "action": "robomimic OSC_POSE: delta position (x0.05 m), delta axis-angle (x0.5 rad), gripper (+1 close)",
        "success": "data/success: 1 once the cube's centre is 0.04 m above the table top, after each action",
        "image": "agentview, upright",
        "seed_start": c.seed_start,
        "mix": mix_text,
        "noise": c.noise,
        "lag": c.lag,
        "max_steps": max_steps,
        "episodes": episodes,
    }});
    let path = writer.finish(&attrs)?;
    println!("lift dataset: {n} episodes, {steps} steps -> {}", path.display());
    Ok(ExitCode::SUCCESS)
}
