//! Recorded actions replayed in the simulator: the actions one episode executed (in
//! the world model, say) stepped from the same reset state and scored exactly.
//!
//! Why: when the world model imagines a policy succeeding more often than MuJoCo
//! sees it succeed, either the imagined frames made the policy act better (then the
//! imagined actions succeed in MuJoCo too) or the imagined dynamics forgave actions
//! that fail for real (then they do not). Replaying the imagined actions separates
//! the two (`simulate --replay-imagined`). The replay runs the simulator branch with
//! a [`Replay`] policy, so it steps, scores and stops at success exactly as that
//! branch does for a real policy.

use std::sync::atomic::{AtomicUsize, Ordering};

use harness::policy::{ActionChunk, Observation, Policy, PolicyError};
use harness::results::EpisodeRow;
use harness::rng::Rng;

use crate::{EngineError, Setup, Start, Timing, Trajectory, sim_branch};

/// A policy that ignores what it sees and hands out one episode's recorded actions in
/// chunks of `horizon`, in order (a batch of one episode).
pub struct Replay {
    name: String,
    obs_horizon: usize,
    horizon: usize,
    actions: Vec<Vec<f32>>,
    next: AtomicUsize,
}

impl Replay {
    /// Replays `actions` under the policy name `name`, which sees `obs_horizon` frames
    /// (the recorded policy's, so the branch keeps the same history).
    pub fn new(name: &str, obs_horizon: usize, horizon: usize, actions: Vec<Vec<f32>>) -> Self {
        Self {
            name: name.to_string(),
            obs_horizon,
            horizon: horizon.max(1),
            actions,
            next: AtomicUsize::new(0),
        }
    }
}

impl Policy for Replay {
    fn name(&self) -> &str {
        &self.name
    }
    fn obs_horizon(&self) -> usize {
        self.obs_horizon
    }
    fn action_horizon(&self) -> usize {
        self.horizon
    }
    fn act(&self, obs: &[Observation], _rngs: &mut [Rng]) -> Result<Vec<ActionChunk>, PolicyError> {
        let input = |message: String| PolicyError::Input { policy: self.name.clone(), message };
        if obs.len() != 1 {
            return Err(input(format!("a replay runs one episode, not a batch of {}", obs.len())));
        }
        let at = self.next.load(Ordering::Relaxed);
        if at >= self.actions.len() {
            return Err(input(format!("all {} recorded actions are replayed", self.actions.len())));
        }
        let end = (at + self.horizon).min(self.actions.len());
        self.next.store(end, Ordering::Relaxed);
        Ok(vec![self.actions[at..end].to_vec()])
    }
}

/// Steps `actions` in the simulator from `seed`'s reset state in chunks of `horizon`
/// (the recorded policy's, so that an episode ends at the end of the same chunk as
/// the simulator branch ends it: the one in which it succeeds), for at most their
/// number of steps, and returns the simulator branch's row, named `name`.
///
/// With `record`, the episode also comes back whole (ending where its row ends: with
/// the chunk that succeeds, or after the last action).
///
/// # Errors
/// No actions, a reset that fails, or a diverging simulation.
pub fn replay_in_sim(
    name: &str,
    (obs_horizon, horizon): (usize, usize),
    seed: u64,
    actions: Vec<Vec<f32>>,
    (s, record): (&Setup, bool),
    timing: &mut Timing,
) -> Result<(EpisodeRow, Option<Trajectory>), EngineError> {
    if actions.is_empty() {
        return Err(EngineError::EmptyChunk { policy: name.to_string() });
    }
    let setup = Setup { max_steps: actions.len(), ..*s };
    let policy = Replay::new(name, obs_horizon, horizon, actions);
    let mut start = Start::new(name, &[seed], &setup)?;
    start.trajectories = record;
    let mut out = sim_branch(&policy, start, &setup, timing)?;
    Ok((out.rows.remove(0), out.episodes.pop()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use harness::policy::Observation;

    fn obs() -> Observation {
        Observation {
            frames: vec![vec![0]],
            size: 1,
            proprio: vec![vec![0.0]],
            robot: vec![Vec::new()],
            exact: None,
            native: None,
        }
    }

    #[test]
    fn hands_out_the_actions_in_chunks_then_refuses() {
        // 5 actions in chunks of 2: [0, 1], [2, 3], [4]; then none is left.
        let r = Replay::new("p", 1, 2, (0..5).map(|a| vec![a as f32]).collect());
        let mut rngs = [Rng::new(0)];
        let mut next = || r.act(&[obs()], &mut rngs);
        assert_eq!(next().unwrap(), vec![vec![vec![0.0], vec![1.0]]]);
        assert_eq!(next().unwrap(), vec![vec![vec![2.0], vec![3.0]]]);
        assert_eq!(next().unwrap(), vec![vec![vec![4.0]]]);
        let err = next().unwrap_err().to_string();
        assert!(err.contains("policy p") && err.contains("all 5 recorded actions"), "{err}");
        let err = r.act(&[obs(), obs()], &mut [Rng::new(0), Rng::new(1)]).unwrap_err().to_string();
        assert!(err.contains("not a batch of 2"), "{err}");
    }
}
