//! The policy interface `rank` drives: batched, framework-free (plain bytes and
//! floats), with the sampling noise supplied by the caller.
//!
//! All episodes of a policy advance in lockstep, so one call serves B episodes.
//! Each episode owns its [`Rng`]; a policy draws that episode's noise only from
//! it, so an episode replays identically in the MuJoCo and the world-model branch
//! and never depends on which other episodes share its batch.

use crate::rng::Rng;

/// What a policy sees of one episode: the last `obs_horizon` frames and agent positions.
#[derive(Clone, Debug, PartialEq)]
pub struct Observation {
    /// Frames, oldest first, each `size x size x 3` bytes (HWC RGB).
    pub frames: Vec<Vec<u8>>,
    /// Agent positions (world units), oldest first, one per frame.
    pub agent_pos: Vec<[f32; 2]>,
    /// Frame side in pixels.
    pub size: usize,
}

/// A chunk of target positions (world units) to execute in order.
pub type ActionChunk = Vec<[f32; 2]>;

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

/// Checks chunks for NaN/inf (an error naming the policy) and clamps out-of-range
/// actions into `[lo, hi]²`; returns how many coordinates were clamped.
///
/// # Errors
/// [`PolicyError::NonFinite`] for the first episode with a non-finite action.
pub fn sanitize(policy: &str, chunks: &mut [ActionChunk], lo: f32, hi: f32) -> Result<usize, PolicyError> {
    let mut clamped = 0;
    for (episode, chunk) in chunks.iter_mut().enumerate() {
        for a in chunk.iter_mut().flat_map(|a| a.iter_mut()) {
            if !a.is_finite() {
                return Err(PolicyError::NonFinite { policy: policy.to_string(), episode });
            }
            if *a < lo || *a > hi {
                *a = a.clamp(lo, hi);
                clamped += 1;
            }
        }
    }
    Ok(clamped)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sanitize_clamps_and_counts() {
        let mut c = vec![vec![[-3.0, 10.0], [600.0, 512.0]]];
        assert_eq!(sanitize("p", &mut c, 0.0, 512.0).unwrap(), 2);
        assert_eq!(c[0], vec![[0.0, 10.0], [512.0, 512.0]]);
    }

    #[test]
    fn sanitize_names_the_policy_on_nan() {
        let mut c = vec![vec![[1.0, 1.0]], vec![[f32::NAN, 0.0]]];
        let e = sanitize("epoch-10", &mut c, 0.0, 512.0).unwrap_err();
        assert_eq!(e.to_string(), "policy epoch-10: non-finite action in episode 1 of the batch");
    }
}
