//! Which 64-frame windows `wm eval` rolls out: each episode's opening, or windows
//! drawn uniformly from every position of every episode (the authors' protocol).
//!
//! The two answer different questions. An episode's first 64 frames always hold the
//! agent's approach and the first contact, the hardest stretch for a world model.
//! The authors' evaluation (spec §9) samples stride-1 windows from a data loader, so
//! most windows start mid-episode, where the block is already moving or at rest near
//! the goal. Paper numbers are only comparable with the second.

use std::ops::Range;

use harness::rng::Rng;
use harness::seed::derive;

use crate::WmEvalError;

/// How `wm eval` picks its 64-frame windows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Windows {
    /// The first frames of each of the first `--episodes` long-enough episodes.
    First,
    /// `--episodes` windows drawn without replacement, uniformly over every start
    /// position of every long-enough episode, from `--seed` (spec §9's protocol).
    Random,
}

/// One chosen window: the episode's index in the dataset and its first frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    /// The episode's index in the dataset.
    pub episode: usize,
    /// The dataset step of its first (context) frame.
    pub start: usize,
}

/// Up to `n` windows of `len` frames from `episodes` (dataset index, frame range),
/// ordered by start frame.
///
/// `First` takes episode openings in dataset order; `Random` draws from all
/// `r.len() - len + 1` starts of each episode with an RNG derived from `seed` only,
/// so the same call always returns the same windows.
pub fn choose(
    episodes: &[(usize, Range<usize>)],
    len: usize,
    n: usize,
    how: Windows,
    seed: u64,
) -> Vec<Window> {
    let long: Vec<&(usize, Range<usize>)> = episodes.iter().filter(|(_, r)| r.len() >= len).collect();
    match how {
        Windows::First => long.iter().take(n).map(|(i, r)| Window { episode: *i, start: r.start }).collect(),
        Windows::Random => {
            let mut all: Vec<Window> = long
                .iter()
                .flat_map(|(i, r)| (r.start..=r.end - len).map(move |start| Window { episode: *i, start }))
                .collect();
            let take = n.min(all.len());
            // Partial Fisher–Yates: the first `take` slots become a uniform sample.
            let mut rng = Rng::new(derive(seed, &[0x77_696e_646f_7773])); // "windows"
            for j in 0..take {
                let pick = j + rng.below((all.len() - j) as u64) as usize;
                all.swap(j, pick);
            }
            all.truncate(take);
            all.sort_by_key(|w| w.start);
            all
        }
    }
}

/// The windows of `len` frames that start at the given steps (`--start`), each
/// checked to lie inside one of `episodes`, ordered by start frame (the filmstrip
/// shows the first).
///
/// # Errors
/// [`WmEvalError::Start`]: a step outside every episode, or too close to its episode's
/// end, named with the episode's range.
pub fn at(
    episodes: &[(usize, Range<usize>)],
    len: usize,
    starts: &[usize],
    which: &str,
) -> Result<Vec<Window>, WmEvalError> {
    starts
        .iter()
        .map(|&start| {
            let Some((i, r)) = episodes.iter().find(|(_, r)| r.contains(&start)) else {
                return Err(WmEvalError::Start(format!("--start {start}: no {which} holds step {start}")));
            };
            if start + len > r.end {
                return Err(WmEvalError::Start(format!(
                    "--start {start}: {which} {i} (steps {}..{}) ends {} steps after it; a video needs {len}",
                    r.start,
                    r.end,
                    r.end - start
                )));
            }
            Ok(Window { episode: *i, start })
        })
        .collect::<Result<Vec<_>, _>>()
        .map(|mut w| {
            w.sort_by_key(|w| w.start);
            w
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three episodes of 5, 2 and 4 frames, stored back to back.
    fn episodes() -> Vec<(usize, Range<usize>)> {
        vec![(0, 0..5), (1, 5..7), (2, 7..11)]
    }

    #[test]
    fn first_takes_the_openings_of_long_enough_episodes() {
        // Windows of 3 frames: episode 1 (2 frames) is too short.
        let w = choose(&episodes(), 3, 5, Windows::First, 0);
        assert_eq!(w, vec![Window { episode: 0, start: 0 }, Window { episode: 2, start: 7 }]);
        assert_eq!(choose(&episodes(), 3, 1, Windows::First, 0).len(), 1);
    }

    #[test]
    fn explicit_starts_are_checked_against_their_episode() {
        let w = at(&episodes(), 3, &[8, 1], "held-out episode").unwrap();
        assert_eq!(w, vec![Window { episode: 0, start: 1 }, Window { episode: 2, start: 8 }]);
        // Step 9 leaves 2 frames (9, 10) in episode 2; step 11 is in no episode.
        let err = at(&episodes(), 3, &[9], "held-out episode").unwrap_err().to_string();
        assert_eq!(err, "--start 9: held-out episode 2 (steps 7..11) ends 2 steps after it; a video needs 3");
        let err = at(&episodes(), 3, &[11], "held-out episode").unwrap_err().to_string();
        assert_eq!(err, "--start 11: no held-out episode holds step 11");
    }

    #[test]
    fn random_covers_every_start_when_asked_for_all() {
        // Episode 0 has starts 0, 1, 2 (5 - 3 + 1 = 3); episode 2 has 7, 8 (4 - 3 + 1 = 2).
        let w = choose(&episodes(), 3, 100, Windows::Random, 9);
        let starts: Vec<usize> = w.iter().map(|w| w.start).collect();
        assert_eq!(starts, vec![0, 1, 2, 7, 8]);
        assert!(w.iter().all(|w| (w.episode == 0) == (w.start < 5)));
    }

    #[test]
    fn random_is_a_function_of_the_seed_and_stays_inside_episodes() {
        let eps: Vec<(usize, Range<usize>)> = (0..20).map(|i| (i, i * 50..i * 50 + 30 + i)).collect();
        let a = choose(&eps, 20, 40, Windows::Random, 3);
        assert_eq!(a, choose(&eps, 20, 40, Windows::Random, 3));
        assert_ne!(a, choose(&eps, 20, 40, Windows::Random, 4));
        assert_eq!(a.len(), 40);
        for w in &a {
            let r = &eps[w.episode].1;
            assert!(r.start <= w.start && w.start + 20 <= r.end, "{w:?} leaves {r:?}");
        }
        let mut distinct = a.clone();
        distinct.dedup();
        assert_eq!(distinct.len(), a.len(), "a window was drawn twice");
    }

    #[test]
    fn random_draws_starts_roughly_uniformly() {
        // One episode of 1,000 starts, 500 drawn: about half fall in each half.
        let eps = vec![(0, 0..1_000 + 63)];
        let w = choose(&eps, 64, 500, Windows::Random, 1);
        let low = w.iter().filter(|w| w.start < 500).count();
        assert!((200..300).contains(&low), "{low} of 500 in the first half");
    }
}
