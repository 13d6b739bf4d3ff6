//! `evalharness collect --scenario lift|can`: a dataset of one of robosuite's
//! tasks in the replay-buffer zarr layout, from a seeded mix of scripted
//! behaviours.
//!
//! The layout is Push-T's with the task's sizes:
//! - `data/img`: the agentview image before each action, `size`² RGB (96 by
//!   default, the paper's size for simulated tasks);
//! - `data/action`: robomimic's 7-D OSC_POSE actions;
//! - `data/state`: the task's 23 columns (object pose, grip-site pose, fingers,
//!   arm joints);
//! - `data/success`: 1 while the task's success holds, after each action.
//!
//! Each episode's behaviour is drawn from `--mix` with a random number derived
//! from its seed, so the dataset is a pure function of the arguments, whatever
//! `--jobs` is.

use std::process::ExitCode;

use anyhow::Result;
use harness::replay::attrs::{DatasetAttrs, EpisodeEntry, Source};
use harness::replay::{EpisodeArrays, ReplaySpec};

use crate::output::dataset::StagedDataset;
use scenarios::robosuite::rollout::{ArmTask, Episode, Perturbation};

use super::collect_mix::{draw, parse_mix_with, with_source};
use crate::cli::CollectArgs;
use crate::progress;
use scenarios::robosuite::runs::{ArmRun, behaviour};

/// Behaviours left out of the default mix: `explore` came after the shipped Lift
/// models' datasets, which were collected with the default, so the default stays
/// what those datasets' commands meant. Ask for it with `--mix`.
const OPT_IN: [&str; 1] = ["explore"];

/// The default `--mix` of a task: half expert episodes, the other half spread
/// evenly over the ways weak policies fail (not the opt-in behaviours).
fn default_mix<T: ArmTask>(task: &T) -> String {
    let all = task.behaviours();
    let flawed: Vec<&str> = all[1..].iter().map(|(n, _)| *n).filter(|n| !OPT_IN.contains(n)).collect();
    let others = flawed.len().max(1) as f64;
    let mut parts = vec![format!("{}=0.5", all[0].0)];
    parts.extend(flawed.iter().map(|n| format!("{n}={}", 0.5 / others)));
    parts.join(",")
}

/// Side of the stored images.
const IMAGE_SIZE: usize = 96;

/// One episode's arrays: the frame before each action, its state row, the
/// action and success after it.
fn episode_arrays<I, B>(ep: &Episode<I, B>) -> EpisodeArrays {
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

/// The robosuite layout: `size`² frames, 7-D actions, `columns` state columns, `data/success`.
pub(super) fn replay_spec(size: usize, columns: usize) -> ReplaySpec {
    ReplaySpec { image_hw: [size, size], action_dim: 7, state_dim: columns, extras: vec!["success".into()] }
}

/// A robosuite dataset's attributes: the task, how the episodes were made (`source`:
/// the scripted mix and perturbation, or `--policy`'s checkpoints), the step limit
/// and one entry per episode.
pub(super) fn dataset_attrs<T: ArmTask>(
    task: &T,
    seed_start: u64,
    source: Source,
    max_steps: usize,
    episodes: Vec<EpisodeEntry>,
) -> DatasetAttrs {
    with_source(dataset_header(task), seed_start, source, max_steps, episodes)
}

/// A robosuite dataset's own attributes: the task, its config and the meaning of
/// each array.
pub(super) fn dataset_header<T: ArmTask>(task: &T) -> DatasetAttrs {
    DatasetAttrs {
        scenario: Some(task.name().to_string()),
        scenario_config: Some(task.config_json()),
        state_columns: Some(task.state_columns().iter().map(ToString::to_string).collect()),
        action: Some(
            "robomimic OSC_POSE: delta position (x0.05 m), delta axis-angle (x0.5 rad), gripper (+1 close)"
                .into(),
        ),
        success: Some("data/success: 1 while the task's success check holds, after each action".into()),
        image: Some("agentview, upright".into()),
        ..DatasetAttrs::new()
    }
}

/// Runs the command.
pub fn run<T: ArmTask>(args: &CollectArgs, task: &T, quiet: bool) -> Result<ExitCode> {
    let c = &args.common;
    let name = task.name();
    let mix_text = args.mix.clone().unwrap_or_else(|| default_mix(task));
    let mix = parse_mix_with(&mix_text, |n| Ok(behaviour(task, n)?))?;
    let max_steps = c.max_steps.map_or(task.max_steps(), |m| m as usize);
    let perturbation = Perturbation { noise: c.noise, lag: c.lag };
    let work: Vec<(u64, T::Behaviour)> =
        harness::seed::range(c.seed_start, c.episodes)?.map(|seed| (seed, draw(&mix, seed))).collect();
    let spec = replay_spec(IMAGE_SIZE, task.state_columns().len());
    let inputs = crate::output::Inputs::new().scenario(&c.scenario);
    let mut writer = StagedDataset::create(&args.out, c.force, &inputs, spec)?;
    let pb = progress::bar(c.episodes, &format!("collect {name}"), quiet);
    let mut episodes = Vec::new();
    let runner = ArmRun { task, perturbation, max_steps, stop_at_success: !args.no_early_stop, jobs: c.jobs };
    runner.run(
        &work,
        |_| Some(IMAGE_SIZE),
        |_, ep| {
            writer.append(&episode_arrays(&ep))?;
            episodes.push(EpisodeEntry {
                seed: Some(ep.seed),
                behaviour: Some(task.behaviour_name(ep.behaviour).to_string()),
                steps: Some(ep.rows.len() as u64),
                success: Some(ep.success),
                ..EpisodeEntry::default()
            });
            pb.inc(1);
            anyhow::Ok(())
        },
    )?;
    pb.finish_and_clear();
    let n = episodes.len();
    let source = Source {
        mix: Some(mix_text),
        noise: Some(c.noise),
        lag: Some(c.lag as u64),
        no_early_stop: Some(args.no_early_stop),
        ..Source::default()
    };
    let attrs = dataset_attrs(task, c.seed_start, source, max_steps, episodes);
    let steps = attrs.total_steps();
    let path = writer.finish(&attrs)?;
    outln!("{name} dataset: {n} episodes, {steps} steps -> {}", path.display());
    Ok(ExitCode::SUCCESS)
}
