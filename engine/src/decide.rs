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

/// Appends the newest frame of each episode that was `active` in this chunk to its
/// recording, so that an episode's recording ends where the episode ended, whichever
/// others ran with it; a no-op when not recording.
pub(crate) fn record_chunk(rec: &mut [Vec<Vec<u8>>], hist: &[VecDeque<Seen>], active: &[usize]) {
    for &i in active {
        if let (Some(r), Some(last)) = (rec.get_mut(i), hist[i].back()) {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_chunks_active_episodes_are_recorded() {
        let seen = |v: u8| Seen {
            frame: vec![v],
            proprio: Vec::new(),
            robot: Vec::new(),
            exact: None,
            native: None,
        };
        let hist: Vec<VecDeque<Seen>> = vec![[seen(1)].into(), [seen(2)].into(), [seen(3)].into()];
        let mut rec = vec![vec![vec![0]]; 3];
        record_chunk(&mut rec, &hist, &[0, 2]);
        // Episode 1 ended before this chunk: its recording ends with its episode.
        assert_eq!(rec, vec![vec![vec![0], vec![1]], vec![vec![0]], vec![vec![0], vec![3]]]);
        let mut none: Vec<Vec<Vec<u8>>> = Vec::new();
        record_chunk(&mut none, &hist, &[0]);
        assert!(none.is_empty(), "not recording: nothing kept");
    }
}
