//! The simulator branch: real frames, the real proprioception, exact scores.
//!
//! The policy sees the task's rendered observations; every executed action is
//! scored exactly from the simulator's state. The judge of imagined frames also
//! reads the frames the policy sees here, and its mean absolute error against
//! the exact score goes into the row (`scorer_abs_error`): how far to trust the
//! imagined branch's scores. With [`Start::observe`] the policy sees each real frame
//! rewritten (an autoencoder's rendering of it), while scores and the judge keep the
//! real frames. Episodes step on rayon.

use std::time::Instant;

use harness::judge::Judge;
use harness::policy::{ActionChunk, Policy};
use harness::results::{Branch, EpisodeRow};
use harness::task::{Env, ScoreKind, Seen};
use rayon::prelude::*;

use crate::EngineError;
use crate::decide::{decide, record_chunk};
use crate::start::{Begin, BranchOut, Observe, Setup, Start, Timing, Track, Trajectory, push, still_active};

/// What one simulator episode returns per chunk.
#[derive(Default)]
struct ChunkOut {
    /// Exact raw score after each executed action.
    raw: Vec<f64>,
    /// The observations the policy will see (the chunk's last `obs_horizon`).
    seen: Vec<Seen>,
    /// Sum of the judge's absolute errors on `seen`.
    err: f64,
    /// With [`Start::trajectories`]: each step's observation frame and state before
    /// the action, and the action.
    steps: Vec<(Vec<u8>, Vec<f64>, Vec<f32>)>,
}

/// Rewrites the frames of `seen` in one call of `f` ([`Start::observe`]).
fn observe<'a>(f: &Observe, seen: impl Iterator<Item = &'a mut Seen>) {
    let mut seen: Vec<&mut Seen> = seen.collect();
    let mut frames: Vec<Vec<u8>> = seen.iter_mut().map(|s| std::mem::take(&mut s.frame)).collect();
    f(&mut frames);
    for (s, frame) in seen.into_iter().zip(frames) {
        s.frame = frame;
    }
}

/// The simulator branch of one batch.
///
/// # Errors
/// A policy error or a diverging simulation.
pub fn sim_branch(
    policy: &dyn Policy,
    mut start: Start,
    s: &Setup,
    timing: &mut Timing,
) -> Result<BranchOut, EngineError> {
    let Begin { name, n, size, kind, o, mut hist, mut rngs, mut track, mut rec } = start.begin(policy, s);
    let mut judge_err = vec![(0.0f64, 0usize); n];
    let (trajectories, run_on) = (start.trajectories, start.run_on);
    let mut traj: Vec<Trajectory> = vec![Trajectory::default(); n];
    for (((t, env), judge), f) in track.iter_mut().zip(&start.envs).zip(&start.judges).zip(&start.first) {
        t.add(env.score(), &kind);
        t.scene = judge.as_ref().and_then(|j| j.scene(&f.frame));
    }
    if let Some(f) = &start.observe {
        observe(f, hist.iter_mut().flat_map(|h| h.iter_mut()));
    }
    let mut steps = 0;
    let mut active: Vec<usize> = (0..n).collect();
    while steps < s.max_steps && !active.is_empty() {
        let (chunks, len) = decide(policy, &hist, &active, size, &mut rngs, s.max_steps - steps, timing)?;
        let ts = Instant::now();
        let mut chunk_of: Vec<Option<&ActionChunk>> = vec![None; n];
        for (&i, ch) in active.iter().zip(&chunks) {
            chunk_of[i] = Some(ch);
        }
        let results = step_chunks(&mut start.envs, &chunk_of, &start.judges, (len, o), trajectories);
        let mut seen: Vec<(usize, Vec<Seen>)> = Vec::with_capacity(active.len());
        for (i, r) in results.into_iter().enumerate() {
            let Some(r) = r else { continue };
            let mut out = r?;
            out.raw.iter().for_each(|&v| track[i].add(v, &kind));
            track[i].steps += len;
            judge_err[i].0 += out.err;
            judge_err[i].1 += out.seen.len();
            if let Some(f) = out.seen.last() {
                track[i].scene = start.judges[i].as_ref().and_then(|j| j.scene(&f.frame));
            }
            seen.push((i, std::mem::take(&mut out.seen)));
            let t = &mut traj[i];
            for ((frame, state, action), raw) in out.steps.into_iter().zip(out.raw) {
                t.frames.push(frame);
                t.states.push(state);
                t.actions.push(action);
                t.raw.push(raw);
            }
        }
        if let Some(f) = &start.observe {
            observe(f, seen.iter_mut().flat_map(|(_, s)| s.iter_mut()));
        }
        for (i, frames) in seen {
            frames.into_iter().for_each(|f| push(&mut hist[i], f, o));
        }
        record_chunk(&mut rec, &hist, &active);
        track.iter_mut().for_each(Track::end_chunk);
        timing.sim_s += ts.elapsed().as_secs_f64();
        steps += len;
        if !run_on {
            active = still_active(&active, &track);
        }
    }
    let (rows, episodes) = finish(&start, (&name, &kind), &track, &judge_err, trajectories.then_some(traj));
    Ok(BranchOut { rows, frames: rec, episodes })
}

/// Steps each episode that has a chunk in `chunk_of` through its first `len` actions, on the
/// worker threads: the raw scores, the last `o` observations (with `judges`' error on
/// them), and with `trajectories` each step's frame, state and action before it. `None` for
/// an episode without a chunk (ended).
fn step_chunks(
    envs: &mut [Box<dyn Env>],
    chunk_of: &[Option<&ActionChunk>],
    judges: &[Option<Box<dyn Judge>>],
    (len, o): (usize, usize),
    trajectories: bool,
) -> Vec<Option<Result<ChunkOut, EngineError>>> {
    envs.par_iter_mut()
        .zip(chunk_of.par_iter())
        .zip(judges.par_iter())
        .map(|((env, chunk), judge)| {
            let chunk = (*chunk)?;
            let mut run = || -> Result<ChunkOut, EngineError> {
                let mut out = ChunkOut { raw: Vec::with_capacity(len), ..ChunkOut::default() };
                for (j, a) in chunk[..len].iter().enumerate() {
                    let before = trajectories.then(|| (env.observe().frame, env.state()));
                    let raw = env.step(a)?;
                    out.raw.push(raw);
                    if let Some((frame, state)) = before {
                        out.steps.push((frame, state, a.to_vec()));
                    }
                    if j + o >= len {
                        let seen = env.observe();
                        if let Some(j) = judge {
                            out.err += (j.score(&seen.frame) - raw).abs();
                        }
                        out.seen.push(seen);
                    }
                }
                Ok(out)
            };
            Some(run())
        })
        .collect()
}

/// The branch's rows (each with its judge's error on the real frames) and, when `traj` was
/// recorded, its whole trajectories, each ending with the last frame.
fn finish(
    start: &Start,
    (name, kind): (&str, &ScoreKind),
    track: &[Track],
    judge_err: &[(f64, usize)],
    traj: Option<Vec<Trajectory>>,
) -> (Vec<EpisodeRow>, Vec<Trajectory>) {
    let n = track.len();
    let rows = (0..n)
        .map(|i| {
            let env = &start.envs[i];
            // The judge's error on the real frames; none without a judge.
            let err = start.judges[i].is_some().then(|| judge_err[i].0 / judge_err[i].1.max(1) as f64);
            track[i]
                .row(name, start.seeds[i], Branch::Sim, kind)
                .with_state(&start.conditions[i])
                .with_state(&env.final_state())
                .with_scorer_error(err)
        })
        .collect();
    let episodes = match traj {
        Some(traj) => traj
            .into_iter()
            .enumerate()
            .map(|(i, mut t)| {
                let env: &dyn Env = start.envs[i].as_ref();
                t.frames.push(env.observe().frame);
                t.success = t.raw.iter().any(|&r| r > kind.threshold());
                (t.seed, t.goal, t.score) = (start.seeds[i], start.goals[i], track[i].best_reward);
                t
            })
            .collect(),
        None => Vec::new(),
    };
    (rows, episodes)
}
