//! Push-T's scripted behaviours and dataset layout behind [`harness::scripted::Scripted`]:
//! what `simulate` and `collect` run, and the layout every Push-T dataset is written in.
//!
//! The layout (diffusion_policy's replay buffer with this project's state row):
//! - `data/img`: the `size`² observation before each action;
//! - `data/action`: the agent's absolute target, world units;
//! - `data/state`: [`STATE_COLUMNS`], the agent and block before the action and the goal;
//! - `data/coverage`: the goal's coverage after each action.

use harness::replay::attrs::DatasetAttrs;
use harness::replay::{EpisodeArrays, ReplaySpec};
use harness::scripted::{EpisodeSink, FrameChoice, Layout, Recorded, Scripted, ScriptedEpisode, Settings};
use harness::task::TaskError;
use serde_json::json;

use super::Pose2;
use super::rollout::{Episode, StepRow};
use super::runs::{BehaviourKind, FrameSpec, Perturbation, Runner, behaviour_label};
use super::task::PushTTask;
use crate::error::ScenarioError;

/// Names of the state columns, stored in the dataset's attributes.
pub const STATE_COLUMNS: [&str; 8] =
    ["agent_x", "agent_y", "block_x", "block_y", "block_theta", "goal_x", "goal_y", "goal_theta"];

/// The behaviours, the expert first.
const BEHAVIOURS: [BehaviourKind; 3] = [BehaviourKind::Expert, BehaviourKind::Explore, BehaviourKind::Decoy];

/// One episode's arrays: the observation before each action, its state row
/// ([`STATE_COLUMNS`]), the action and the coverage after it.
fn episode_arrays(ep: &Episode) -> EpisodeArrays {
    let steps = ep.rows.len();
    let mut arrays = EpisodeArrays::default();
    for f in &ep.frames[..steps.min(ep.frames.len())] {
        arrays.img.extend_from_slice(f);
    }
    let g = ep.goal;
    let mut coverage = Vec::with_capacity(steps);
    for r in &ep.rows {
        arrays.action.extend(r.action.map(|v| v as f32));
        let s = [r.agent[0], r.agent[1], r.block.x, r.block.y, r.block.theta, g.x, g.y, g.theta];
        arrays.state.extend(s.map(|v| v as f32));
        coverage.push(r.coverage as f32);
    }
    arrays.extras.push(coverage);
    arrays
}

/// `simulate`'s `episodes.jsonl` lines of an episode: each step's agent and block before
/// the action, the goal, the action and the coverage after it.
fn step_lines(ep: &Episode) -> Vec<String> {
    ep.rows
        .iter()
        .map(|r| {
            json!({
                "seed": ep.seed,
                "step": r.step,
                "agent": r.agent,
                "block": r.block.to_array(),
                "goal": ep.goal.to_array(),
                "action": r.action,
                "coverage": r.coverage,
            })
            .to_string()
        })
        .collect()
}

/// A recorded Push-T episode (its counts checked: [`Recorded::check_counts`]) as
/// [`Episode`]: each step's state (agent x, y, block x, y, θ) before the action, the action
/// and the coverage after it.
fn recorded_episode(t: &Recorded<'_>) -> Result<Episode, ScenarioError> {
    let bad = |message: String| ScenarioError::Recorded { seed: t.seed, message };
    let g = t.goal.ok_or_else(|| bad("the episode has no goal pose".into()))?;
    let rows = t
        .states
        .iter()
        .zip(t.actions)
        .zip(t.raw)
        .enumerate()
        .map(|(j, ((s, a), &coverage))| match (&s[..], &a[..]) {
            (&[ax, ay, bx, by, bth], &[x, y]) => Ok(StepRow {
                step: j as u32,
                agent: [ax, ay],
                block: Pose2::new(bx, by, bth),
                action: [f64::from(x), f64::from(y)],
                coverage,
            }),
            _ => Err(bad(format!(
                "step {j}: state of {} entries or action of {}, expected 5 and 2",
                s.len(),
                a.len()
            ))),
        })
        .collect::<Result<_, _>>()?;
    Ok(Episode {
        seed: t.seed,
        goal: Pose2::new(g[0], g[1], g[2]),
        rows,
        frames: t.frames.to_vec(),
        score: t.score,
        success: t.success,
    })
}

impl Scripted for PushTTask {
    fn behaviours(&self) -> Vec<&'static str> {
        BEHAVIOURS.iter().map(|b| b.name()).collect()
    }

    fn default_mix(&self) -> String {
        "expert=0.8,explore=0.2".into()
    }

    fn early_stop_optional(&self) -> bool {
        false
    }

    fn second_renderer(&self) -> bool {
        true
    }

    fn config_json(&self) -> serde_json::Value {
        serde_json::to_value(self.config()).unwrap_or(serde_json::Value::Null)
    }

    fn state_columns(&self) -> Vec<String> {
        STATE_COLUMNS.iter().map(|c| (*c).to_string()).collect()
    }

    fn layout(&self) -> Layout {
        let size = self.config().render.size as usize;
        Layout {
            spec: ReplaySpec {
                image_hw: [size, size],
                action_dim: 2,
                state_dim: 8,
                extras: vec!["coverage".into()],
            },
            header: DatasetAttrs {
                scenario: Some("pusht".into()),
                scenario_config: Some(self.config_json()),
                state_columns: Some(self.state_columns()),
                action: Some("absolute agent target position, world units".into()),
                coverage: Some("data/coverage: coverage after each action".into()),
                ..DatasetAttrs::new()
            },
        }
    }

    fn recorded_arrays(&self, episode: &Recorded<'_>) -> Result<EpisodeArrays, TaskError> {
        episode.check_counts().map_err(TaskError::new)?;
        Ok(episode_arrays(&recorded_episode(episode).map_err(TaskError::new)?))
    }

    fn run(
        &self,
        work: &[(u64, usize)],
        settings: &Settings,
        frames: &FrameChoice<'_>,
        done: &mut EpisodeSink<'_>,
    ) -> Result<(), TaskError> {
        let perturbation = Perturbation { noise: settings.noise, lag: settings.lag };
        let max_steps = u32::try_from(settings.max_steps).unwrap_or(u32::MAX);
        let runner = Runner::on_model(
            self.config().clone(),
            self.model().clone(),
            settings.jobs,
            Some(max_steps),
            perturbation,
        )
        .map_err(TaskError::new)?;
        let kinds: Vec<(u64, BehaviourKind)> =
            work.iter().map(|&(seed, b)| (seed, BEHAVIOURS[b.min(BEHAVIOURS.len() - 1)])).collect();
        runner.run(
            &kinds,
            |i| frames(i).map(|r| FrameSpec { size: r.size, beside_mujoco: r.beside_reference }),
            |i, ep| {
                let steps = ep.rows.len();
                done(
                    i,
                    ScriptedEpisode {
                        seed: ep.seed,
                        behaviour: behaviour_label(kinds[i].1, perturbation),
                        arrays: episode_arrays(&ep),
                        score: ep.score,
                        success: ep.success,
                        steps,
                        steps_to_success: ep.success.then_some(steps),
                        step_lines: step_lines(&ep),
                        initial_state: None,
                        frames: ep.frames,
                    },
                )
            },
        )
    }
}
