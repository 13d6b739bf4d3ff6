//! What both branches do alike at each decision: ask the policy for the active
//! episodes' action chunks (each episode with its own noise stream), and record
//! the newest frames for filmstrips.

use std::collections::VecDeque;
use std::time::Instant;

use harness::policy::{ActionChunk, Observation, Policy};
use harness::rng::Rng;
use harness::task::Seen;

use crate::EngineError;
use crate::start::{Timing, obs_of};

/// Appends every episode's newest frame to its recording (an ended episode repeats its
/// last one, so both branches' strips stay aligned); a no-op when not recording.
pub(crate) fn record_chunk(rec: &mut [Vec<Vec<u8>>], hist: &[VecDeque<Seen>]) {
    for (r, h) in rec.iter_mut().zip(hist) {
        if let Some(last) = h.back() {
            r.push(last.frame.clone());
        }
    }
}

/// One batched decision for the `active` episodes: their chunks (in `active`'s order)
/// and how many actions to execute (the shortest chunk, at most `left`). Each
/// episode keeps its own noise stream, whichever others are still running.
///
/// # Errors
/// A policy error, unusable observations, or an empty or missing chunk.
pub(crate) fn decide(
    policy: &dyn Policy,
    hist: &[VecDeque<Seen>],
    active: &[usize],
    size: usize,
    rngs: &mut [Rng],
    left: usize,
    timing: &mut Timing,
) -> Result<(Vec<ActionChunk>, usize), EngineError> {
    let tp = Instant::now();
    let obs: Vec<Observation> = active.iter().map(|&i| obs_of(&hist[i], size)).collect();
    let mut sub: Vec<Rng> = active.iter().map(|&i| rngs[i].clone()).collect();
    let chunks = policy.act(&obs, &mut sub)?;
    for (&i, r) in active.iter().zip(sub) {
        rngs[i] = r;
    }
    timing.policy_s += tp.elapsed().as_secs_f64();
    let len = chunks.iter().map(Vec::len).min().unwrap_or(0).min(left);
    if len == 0 || chunks.len() != active.len() {
        return Err(EngineError::EmptyChunk { policy: policy.name().to_string() });
    }
    Ok((chunks, len))
}
