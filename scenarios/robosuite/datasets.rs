//! Lift's and Can's scripted behaviours and dataset layout behind
//! [`harness::scripted::Scripted`], once for every robosuite task ([`RobosuiteTask`]).
//!
//! The layout is Push-T's with the task's sizes:
//! - `data/img`: the agentview image before each action, `size`² RGB (96, the paper's
//!   size for simulated tasks);
//! - `data/action`: robomimic's 7-D OSC_POSE actions;
//! - `data/state`: the task's state columns (object pose, grip-site pose, fingers, arm
//!   joints);
//! - `data/success`: 1 while the task's success holds, after each action.

use harness::replay::attrs::DatasetAttrs;
use harness::replay::{EpisodeArrays, ReplaySpec};
use harness::scripted::{EpisodeSink, FrameChoice, Layout, Recorded, Scripted, ScriptedEpisode, Settings};
use harness::task::{Task, TaskError};
use serde::Serialize;

use super::arm_sim::{ArmScene, ArmSim};
use super::rollout::{Episode, Perturbation};
use super::runs::ArmRun;
use super::task::{IMAGE_SIZE, RobosuiteTask};

/// Behaviours left out of the default mix: `explore` came after the shipped Lift
/// models' datasets, which were collected with the default, so the default stays
/// what those datasets' commands meant. Ask for it with `--mix`.
const OPT_IN: [&str; 1] = ["explore"];

/// One line of `simulate`'s `episodes.jsonl`.
#[derive(Serialize)]
struct StepLine<'a> {
    seed: u64,
    step: u32,
    state: &'a [f64],
    action: [f64; 7],
    success: bool,
}

/// One line of `simulate`'s `initial_states.jsonl`.
#[derive(Serialize)]
struct InitLine<'a, I: Serialize> {
    seed: u64,
    #[serde(flatten)]
    init: &'a I,
}

/// One episode's arrays: the frame before each action, its state row, the action and
/// success after it.
fn episode_arrays<I, B>(ep: &Episode<I, B>) -> EpisodeArrays {
    let mut arrays = EpisodeArrays::default();
    for f in &ep.frames[..ep.rows.len().min(ep.frames.len())] {
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

/// A finished episode as the data commands write it.
fn scripted_episode<S: ArmScene>(
    task: &ArmSim<S>,
    ep: Episode<S::Init, S::Behaviour>,
) -> Result<ScriptedEpisode, TaskError> {
    let mut step_lines = Vec::with_capacity(ep.rows.len());
    for r in &ep.rows {
        let line =
            StepLine { seed: ep.seed, step: r.step, state: &r.state, action: r.action, success: r.success };
        step_lines.push(serde_json::to_string(&line).map_err(TaskError::new)?);
    }
    let init = serde_json::to_string(&InitLine { seed: ep.seed, init: &ep.init }).map_err(TaskError::new)?;
    Ok(ScriptedEpisode {
        seed: ep.seed,
        behaviour: task.behaviour_name(ep.behaviour).to_string(),
        arrays: episode_arrays(&ep),
        score: if ep.success { 1.0 } else { 0.0 },
        success: ep.success,
        steps: ep.rows.len(),
        steps_to_success: ep.rows.iter().position(|r| r.success).map(|s| s + 1),
        step_lines,
        initial_state: Some(init),
        frames: ep.frames,
    })
}

impl<S: ArmScene> Scripted for RobosuiteTask<S> {
    fn behaviours(&self) -> Vec<&'static str> {
        self.sim().behaviours().iter().map(|(n, _)| *n).collect()
    }

    /// Half expert episodes, the other half spread evenly over the ways weak policies fail
    /// (not the opt-in behaviours).
    fn default_mix(&self) -> String {
        let all = self.sim().behaviours();
        let flawed: Vec<&str> = all[1..].iter().map(|(n, _)| *n).filter(|n| !OPT_IN.contains(n)).collect();
        let others = flawed.len().max(1) as f64;
        let mut parts = vec![format!("{}=0.5", all[0].0)];
        parts.extend(flawed.iter().map(|n| format!("{n}={}", 0.5 / others)));
        parts.join(",")
    }

    fn early_stop_optional(&self) -> bool {
        true
    }

    fn config_json(&self) -> serde_json::Value {
        self.sim().config_json()
    }

    fn state_columns(&self) -> Vec<String> {
        self.sim().state_columns().iter().map(ToString::to_string).collect()
    }

    fn layout(&self) -> Layout {
        let columns = self.sim().state_columns().len();
        Layout {
            spec: ReplaySpec {
                image_hw: [IMAGE_SIZE, IMAGE_SIZE],
                action_dim: 7,
                state_dim: columns,
                extras: vec!["success".into()],
            },
            header: DatasetAttrs {
                scenario: Some(self.sim().name().to_string()),
                scenario_config: Some(self.config_json()),
                state_columns: Some(self.state_columns()),
                action: Some(
                    "robomimic OSC_POSE: delta position (x0.05 m), delta axis-angle (x0.5 rad), gripper (+1 close)"
                        .into(),
                ),
                success: Some("data/success: 1 while the task's success check holds, after each action".into()),
                image: Some("agentview, upright".into()),
                ..DatasetAttrs::new()
            },
        }
    }

    fn recorded_arrays(&self, episode: &Recorded<'_>) -> Result<EpisodeArrays, TaskError> {
        let columns = self.sim().state_columns().len();
        let threshold = self.score_kind().threshold();
        episode.success_arrays((IMAGE_SIZE, columns, 7), threshold).map_err(TaskError::new)
    }

    fn run(
        &self,
        work: &[(u64, usize)],
        settings: &Settings,
        frames: &FrameChoice<'_>,
        done: &mut EpisodeSink<'_>,
    ) -> Result<(), TaskError> {
        let sim = self.sim();
        let all = sim.behaviours();
        let kinds: Vec<(u64, S::Behaviour)> =
            work.iter().map(|&(seed, b)| (seed, all[b.min(all.len() - 1)].1)).collect();
        let runner = ArmRun {
            task: sim,
            perturbation: Perturbation { noise: settings.noise, lag: settings.lag },
            max_steps: settings.max_steps,
            stop_at_success: settings.stop_at_success,
            jobs: settings.jobs,
        };
        runner.run(&kinds, |i| frames(i).map(|r| r.size), |i, ep| done(i, scripted_episode(sim, ep)?))
    }
}
