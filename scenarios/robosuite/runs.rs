//! Lift's and Can's scripted behaviours by name, and many episodes of them run in
//! parallel, deterministically (`collect`, `simulate`; Push-T's are `pusht::runs`).
//!
//! Episodes run on a pool of worker threads in batches and come back in seed order;
//! every random stream of an episode derives from its seed, so any number of threads
//! gives byte-identical episodes.

use rayon::prelude::*;

use super::arm_sim::{ArmScene, ArmSim};
use super::renderer::release_renderer;
use super::rollout::{Episode, Perturbation, RunLimits};
use crate::error::ScenarioError;

/// The behaviour of `task` called `name` (`--policy`, `--mix`).
///
/// # Errors
/// [`ScenarioError::UnknownBehaviour`] listing the task's behaviours.
pub fn behaviour<S: ArmScene>(task: &ArmSim<S>, name: &str) -> Result<S::Behaviour, ScenarioError> {
    let all = task.behaviours();
    all.iter().find(|(n, _)| *n == name).map(|(_, b)| *b).ok_or_else(|| {
        let names: Vec<&str> = all.iter().map(|(n, _)| *n).collect();
        ScenarioError::UnknownBehaviour {
            what: format!("{} behaviour", task.name()),
            name: name.into(),
            listed: format!(": {}", names.join(", ")),
        }
    })
}

/// An episode of `S`'s.
type ArmEpisode<S> = Episode<<S as ArmScene>::Init, <S as ArmScene>::Behaviour>;

/// How a batch of episodes runs.
pub struct ArmRun<'a, S: ArmScene> {
    /// The task.
    pub task: &'a ArmSim<S>,
    /// Noise and lag on the behaviours' actions.
    pub perturbation: Perturbation,
    /// Step limit per episode.
    pub max_steps: usize,
    /// End an episode at its first success.
    pub stop_at_success: bool,
    /// Worker threads.
    pub jobs: usize,
}

impl<S: ArmScene> ArmRun<'_, S> {
    /// Runs `work` on the worker threads in batches, handing the episodes to
    /// `done` in order; `frames(i)` asks episode `i` for frames of that side.
    ///
    /// # Errors
    /// Threads that cannot be started, the first episode that fails
    /// ([`ScenarioError::Episode`], naming the task, seed and behaviour), or what `done`
    /// returns.
    pub fn run<E: From<ScenarioError>>(
        &self,
        work: &[(u64, S::Behaviour)],
        frames: impl Fn(usize) -> Option<usize> + Sync,
        mut done: impl FnMut(usize, Episode<S::Init, S::Behaviour>) -> Result<(), E>,
    ) -> Result<(), E> {
        let jobs = self.jobs.max(1);
        let pool =
            rayon::ThreadPoolBuilder::new().num_threads(jobs).build().map_err(ScenarioError::Threads)?;
        let result = self.run_in(&pool, jobs, work, frames, &mut done);
        // Free every worker's GL context while the workers are alive.
        pool.broadcast(|_| release_renderer());
        result
    }

    fn run_in<E: From<ScenarioError>>(
        &self,
        pool: &rayon::ThreadPool,
        jobs: usize,
        work: &[(u64, S::Behaviour)],
        frames: impl Fn(usize) -> Option<usize> + Sync,
        done: &mut impl FnMut(usize, Episode<S::Init, S::Behaviour>) -> Result<(), E>,
    ) -> Result<(), E> {
        let batch = jobs * 4;
        for (b, chunk) in work.chunks(batch).enumerate() {
            let results: Vec<Result<ArmEpisode<S>, ScenarioError>> = pool.install(|| {
                chunk
                    .par_iter()
                    .enumerate()
                    .map(|(k, &(seed, kind))| {
                        let limits = RunLimits {
                            max_steps: self.max_steps,
                            stop_at_success: self.stop_at_success,
                            frame_size: frames(b * batch + k),
                        };
                        self.task.episode(seed, kind, self.perturbation, limits).map_err(|e| {
                            ScenarioError::Episode {
                                scenario: format!("{} ", self.task.name()),
                                seed,
                                behaviour: self.task.behaviour_name(kind).to_string(),
                                source: Box::new(e),
                            }
                        })
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
