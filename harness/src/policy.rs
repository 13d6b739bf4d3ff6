//! The policy interface `rank` drives: batched, framework-free (plain bytes and
//! floats), with the sampling noise supplied by the caller.
//!
//! All episodes of a policy advance in lockstep, so one call serves B episodes.
//! Each episode owns its [`Rng`]; a policy draws that episode's noise only from
//! it, so an episode replays identically in the MuJoCo and the world-model branch
//! and never depends on which other episodes share its batch.

use crate::rng::Rng;

/// What a policy sees of one episode: the last `obs_horizon` frames and the
/// proprioceptive vectors seen with them.
#[derive(Clone, Debug, PartialEq)]
pub struct Observation {
    /// Frames, oldest first, each `size x size x 3` bytes (HWC RGB).
    pub frames: Vec<Vec<u8>>,
    /// Proprioception, oldest first, one vector per frame, with the entries the
    /// task's observation spec names (Push-T: the agent's position in world units).
    pub proprio: Vec<Vec<f32>>,
    /// The robot's state, oldest first, one vector per frame, laid out as the task's
    /// [`crate::task_spec::ObservationSpec::robot`] (empty vectors where it gives none).
    pub robot: Vec<Vec<f32>>,
    /// Frame side in pixels.
    pub size: usize,
    /// Every frame's values before rounding to bytes (HWC, [0, 1], unclamped), when the
    /// frames are a world model's and the run keeps them (`rank --float-frames`); policies
    /// that read floats use them, the others read `frames`.
    pub exact: Option<Vec<Vec<f32>>>,
    /// Every frame at the side the camera rendered it at, oldest first, where the scene
    /// renders at another side and resizes ([`crate::task_spec::Seen::native`]): a policy trained
    /// at that side reads these instead of resizing `frames` back. Absent in imagination.
    pub native: Option<Vec<crate::task_spec::NativeFrame>>,
}

/// Actions to execute in order, each with the task's action dimension (Push-T: a
/// target position in world units; robomimic: 6 end-effector deltas and a gripper
/// command).
pub type ActionChunk = Vec<Vec<f32>>;

/// Why a policy could not act.
#[derive(Debug, thiserror::Error)]
pub enum PolicyError {
    /// The policy produced NaN or infinite actions.
    #[error("policy {policy}: non-finite action in episode {episode} of the batch")]
    NonFinite {
        /// The policy.
        policy: String,
        /// Index within the batch.
        episode: usize,
    },
    /// Observations the policy cannot take.
    #[error("policy {policy}: {message}")]
    Input {
        /// The policy.
        policy: String,
        /// What is wrong.
        message: String,
    },
}

/// A batched closed-loop policy.
pub trait Policy: Send + Sync {
    /// The policy's name (its checkpoint directory name).
    fn name(&self) -> &str;
    /// Frames per observation.
    fn obs_horizon(&self) -> usize;
    /// Actions executed per decision.
    fn action_horizon(&self) -> usize;
    /// One action chunk per observation; `rngs[i]` is episode i's noise stream.
    ///
    /// # Errors
    /// [`PolicyError`] naming the policy for unusable observations or non-finite output.
    fn act(&self, obs: &[Observation], rngs: &mut [Rng]) -> Result<Vec<ActionChunk>, PolicyError>;
}

/// Checks chunks for NaN/inf (an error naming the policy) and clamps each action's
/// entry d into `[low[d], high[d]]`; returns how many entries were clamped.
///
/// # Errors
/// [`PolicyError::NonFinite`] for the first episode with a non-finite action;
/// [`PolicyError::Input`] for an action whose size is not the bounds'.
pub fn sanitize(
    policy: &str,
    chunks: &mut [ActionChunk],
    low: &[f32],
    high: &[f32],
) -> Result<usize, PolicyError> {
    let mut clamped = 0;
    for (episode, chunk) in chunks.iter_mut().enumerate() {
        for action in chunk.iter_mut() {
            if action.len() != low.len() || action.len() != high.len() {
                return Err(PolicyError::Input {
                    policy: policy.to_string(),
                    message: format!(
                        "episode {episode}: an action has {} entries, the task takes {}",
                        action.len(),
                        low.len()
                    ),
                });
            }
            for (a, (&lo, &hi)) in action.iter_mut().zip(low.iter().zip(high)) {
                if !a.is_finite() {
                    return Err(PolicyError::NonFinite { policy: policy.to_string(), episode });
                }
                if *a < lo || *a > hi {
                    *a = a.clamp(lo, hi);
                    clamped += 1;
                }
            }
        }
    }
    Ok(clamped)
}

#[cfg(test)]
mod tests {
    use super::*;

    const LOW: [f32; 2] = [0.0, 0.0];
    const HIGH: [f32; 2] = [512.0, 512.0];

    #[test]
    fn sanitize_clamps_and_counts() {
        let mut c = vec![vec![vec![-3.0, 10.0], vec![600.0, 512.0]]];
        assert_eq!(sanitize("p", &mut c, &LOW, &HIGH).unwrap(), 2);
        assert_eq!(c[0], vec![vec![0.0, 10.0], vec![512.0, 512.0]]);
    }

    #[test]
    fn sanitize_clamps_each_entry_to_its_own_bounds() {
        // robomimic-like: six deltas in [-1, 1] and a gripper command in [-1, 1];
        // here the last entry is bounded by [0, 0.5] to tell the bounds apart.
        let (low, high) = ([-1.0; 3].to_vec(), vec![1.0, 1.0, 0.5]);
        let mut c = vec![vec![vec![-2.0, 0.3, 0.9]]];
        assert_eq!(sanitize("p", &mut c, &low, &high).unwrap(), 2);
        assert_eq!(c[0][0], vec![-1.0, 0.3, 0.5]);
    }

    #[test]
    fn sanitize_names_the_policy_on_nan() {
        let mut c = vec![vec![vec![1.0, 1.0]], vec![vec![f32::NAN, 0.0]]];
        let e = sanitize("epoch-10", &mut c, &LOW, &HIGH).unwrap_err();
        assert_eq!(e.to_string(), "policy epoch-10: non-finite action in episode 1 of the batch");
    }

    #[test]
    fn sanitize_refuses_an_action_of_the_wrong_size() {
        let mut c = vec![vec![vec![1.0, 1.0, 1.0]]];
        let e = sanitize("epoch-10", &mut c, &LOW, &HIGH).unwrap_err();
        assert_eq!(e.to_string(), "policy epoch-10: episode 0: an action has 3 entries, the task takes 2");
    }
}
