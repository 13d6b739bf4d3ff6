//! Recorded MuJoCo episodes ([`engine::Trajectory`]) written as a training dataset,
//! in the zarr layout of the task's scripted `collect`.
//!
//! Why one place: `collect --policy` records policy checkpoints' closed-loop
//! rollouts, and `simulate --replay-imagined --record` the MuJoCo replays of the
//! actions a policy took in the world model. Both feed the same trainers, so both
//! must write the same layout: Push-T's (agent and block poses, coverage) or the
//! robosuite one (agentview frames, 7-D actions, state columns, `data/success`).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use engine::Trajectory;
use harness::replay::EpisodeArrays;

use crate::output::Inputs;
use crate::output::dataset::StagedDataset;
use harness::replay::attrs::{DatasetAttrs, EpisodeEntry, Source};
use harness::task::Task;
use scenarios::pusht::rollout::{Episode, StepRow};
use scenarios::pusht::{Pose2, PushTConfig, PushTTask};
use scenarios::robosuite::task::{ArmEngine, RobosuiteTask};

use super::collect::{dataset_attrs, episode_arrays, episode_attr, replay_spec};
use super::collect_mix::with_source;

/// How a scenario's recorded episodes are laid out in a dataset.
pub(super) enum Layout {
    /// Push-T's layout.
    PushT(Box<PushTConfig>),
    /// A robosuite task's layout; `header` holds the task's dataset attributes.
    Arm { size: usize, columns: usize, threshold: f64, header: Box<DatasetAttrs> },
}

impl Layout {
    /// The scenario `spec`'s task and its dataset layout, from one load of the scenario.
    pub fn load(spec: &str) -> Result<(Box<dyn Task>, Self)> {
        let what = || format!("loading scenario {spec}");
        Ok(match scenarios::scenario(spec).with_context(what)? {
            scenarios::Scenario::PushT(cfg) => {
                (Box::new(PushTTask::new((*cfg).clone()).with_context(what)?), Self::PushT(cfg))
            }
            scenarios::Scenario::Lift(cfg) => {
                Self::arm(scenarios::lift::LiftSim::new(cfg).with_context(what)?)
            }
            scenarios::Scenario::Can(cfg) => Self::arm(scenarios::can::CanSim::new(cfg).with_context(what)?),
        })
    }

    fn arm<T: ArmEngine + 'static>(sim: T) -> (Box<dyn Task>, Self) {
        let task = RobosuiteTask::new(sim);
        let layout = Self::Arm {
            size: task.observation_spec().image_size,
            columns: task.sim().state_columns().len(),
            threshold: task.score_kind().threshold(),
            header: Box::new(super::collect_arm::dataset_header(task.sim())),
        };
        (Box::new(task), layout)
    }
}

/// A dataset being written, episode by episode; nothing appears at its path until
/// [`Sink::finish`] (it is staged into `PATH.partial`, [`StagedDataset`]).
pub(super) struct Sink {
    writer: StagedDataset,
    layout: Layout,
}

impl Sink {
    /// A dataset at `out` in `layout` for a command reading `inputs` (refused if `out`
    /// exists, unless `force`, or if it overlaps an input).
    pub fn create(layout: Layout, out: &Path, force: bool, inputs: &Inputs) -> Result<Self> {
        let spec = match &layout {
            Layout::PushT(cfg) => replay_spec(cfg.render.size as usize),
            Layout::Arm { size, columns, .. } => super::collect_arm::replay_spec(*size, *columns),
        };
        Ok(Self { writer: StagedDataset::create(out, force, inputs, spec)?, layout })
    }

    /// Appends one episode, labelled `behaviour`; returns its score and its entry in
    /// the dataset's attributes.
    pub fn append(&mut self, t: &Trajectory, behaviour: &str) -> Result<(f64, EpisodeEntry)> {
        match &self.layout {
            Layout::PushT(_) => {
                let ep = pusht_episode(t)?;
                self.writer.append(&episode_arrays(&ep))?;
                Ok((ep.score, episode_attr(&ep, behaviour)))
            }
            Layout::Arm { size, columns, threshold, .. } => {
                self.writer.append(&arm_arrays(t, *size, *columns, *threshold)?)?;
                let attr = EpisodeEntry {
                    seed: Some(t.seed),
                    behaviour: Some(behaviour.to_string()),
                    steps: Some(t.actions.len() as u64),
                    success: Some(t.success),
                    ..EpisodeEntry::default()
                };
                Ok((t.score, attr))
            }
        }
    }

    /// Writes the attributes (how the episodes were made, the step limit, one entry
    /// per episode) and moves the dataset into place; returns its path.
    pub fn finish(
        self,
        seed_start: u64,
        source: Source,
        max_steps: usize,
        episodes: Vec<EpisodeEntry>,
    ) -> Result<PathBuf> {
        let attrs = match self.layout {
            Layout::PushT(cfg) => dataset_attrs(&cfg, seed_start, source, max_steps, episodes),
            Layout::Arm { header, .. } => with_source(*header, seed_start, source, max_steps, episodes),
        };
        Ok(self.writer.finish(&attrs)?)
    }
}

/// A recorded robosuite episode's arrays: the frame and state before each action, the
/// action, and whether the task succeeded after it (raw score above `threshold`).
pub(super) fn arm_arrays(
    t: &Trajectory,
    size: usize,
    columns: usize,
    threshold: f64,
) -> Result<EpisodeArrays> {
    let n = t.actions.len();
    if t.frames.len() < n || t.states.len() != n || t.raw.len() != n {
        bail!("{} frames, {} states, {} scores for {n} actions", t.frames.len(), t.states.len(), t.raw.len());
    }
    let mut arrays = EpisodeArrays::default();
    for (j, ((f, s), a)) in t.frames.iter().zip(&t.states).zip(&t.actions).enumerate() {
        if f.len() != size * size * 3 || s.len() != columns || a.len() != 7 {
            bail!(
                "step {j}: frame of {} bytes, state of {} entries or action of {}, expected {}, {columns} and 7",
                f.len(),
                s.len(),
                a.len(),
                size * size * 3
            );
        }
        arrays.img.extend_from_slice(f);
        arrays.state.extend(s.iter().map(|&v| v as f32));
        arrays.action.extend_from_slice(a);
    }
    arrays.extras.push(t.raw.iter().map(|&r| if r > threshold { 1.0 } else { 0.0 }).collect());
    Ok(arrays)
}

/// A recorded Push-T episode in the dataset layout of `collect`: each step's state
/// (agent x, y, block x, y, θ) before the action, the action and the coverage after it.
fn pusht_episode(t: &Trajectory) -> Result<Episode> {
    let g = t.goal.context("the episode has no goal pose")?;
    let rows = t
        .states
        .iter()
        .zip(&t.actions)
        .zip(&t.raw)
        .enumerate()
        .map(|(j, ((s, a), &coverage))| match (&s[..], &a[..]) {
            (&[ax, ay, bx, by, bth], &[x, y]) => Ok(StepRow {
                step: j as u32,
                agent: [ax, ay],
                block: Pose2::new(bx, by, bth),
                action: [f64::from(x), f64::from(y)],
                coverage,
            }),
            _ => bail!("step {j}: state of {} entries or action of {}, expected 5 and 2", s.len(), a.len()),
        })
        .collect::<Result<_>>()?;
    let (seed, score, success) = (t.seed, t.score, t.success);
    Ok(Episode { seed, goal: Pose2::new(g[0], g[1], g[2]), rows, frames: t.frames.clone(), score, success })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trajectory(n: usize, size: usize, columns: usize) -> Trajectory {
        Trajectory {
            seed: 7,
            frames: vec![vec![1; size * size * 3]; n + 1],
            states: vec![vec![0.5; columns]; n],
            actions: vec![vec![0.1; 7]; n],
            raw: (0..n).map(|j| j as f64 / n as f64).collect(),
            goal: None,
            score: 0.75,
            success: true,
        }
    }

    #[test]
    fn arm_arrays_mark_success_after_each_action_above_the_threshold() {
        // raw after each of 4 actions: 0, 0.25, 0.5, 0.75; above 0.4: the last two.
        let a = arm_arrays(&trajectory(4, 2, 3), 2, 3, 0.4).unwrap();
        assert_eq!(a.extras, vec![vec![0.0, 0.0, 1.0, 1.0]]);
        // 4 frames of 2·2·3 bytes (the final frame is not stored), 4·3 states, 4·7 actions.
        assert_eq!((a.img.len(), a.state.len(), a.action.len()), (48, 12, 28));
    }

    #[test]
    fn arm_arrays_name_the_step_of_a_wrong_shape() {
        let mut t = trajectory(3, 2, 3);
        t.actions[1] = vec![0.0; 6];
        let err = arm_arrays(&t, 2, 3, 0.5).unwrap_err().to_string();
        assert!(err.contains("step 1") && err.contains("action of 6"), "{err}");
        let mut t = trajectory(3, 2, 3);
        t.states.pop();
        let err = arm_arrays(&t, 2, 3, 0.5).unwrap_err().to_string();
        assert!(err.contains("2 states") && err.contains("3 actions"), "{err}");
    }
}
