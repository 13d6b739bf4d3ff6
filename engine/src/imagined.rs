//! The world-model branch: imagined frames only, scored by the task's judge.
//!
//! The history starts as the first observation repeated; each action chunk is
//! imagined in one-pass chunks of F frames; the policy sees only decoded imagined
//! frames, with the proprioception the task's [`Imagination`] integrates from the
//! commanded actions (Push-T: the last commanded target standing in for the agent
//! position, as in DriftWorld's evaluation). Only the frames the policy sees (the
//! last `obs_horizon` of each chunk) are decoded to pixels, and those are scored by
//! the episode's [`Judge`](harness::judge::Judge); with `Setup::judge_every_frame` every
//! generated frame is decoded and scored, as the official evaluation does. The model's own
//! history is its raw predictions (unclamped, unquantised), as there; the policy sees bytes. A goal-free world model
//! (`train world-model --goal-free`) starts from the first frame in its view and
//! each decoded frame gets the goal drawn back before the policy, the judge or a
//! recording sees it. Nothing here reads the simulator after the reset.
//!
//! [`Imagination`]: harness::task::Imagination

use std::time::Instant;

use harness::judge::Judge;
use harness::results::{Branch, EpisodeRow};
use harness::rng::Rng;
use harness::seed::{derive, fnv1a};
use harness::task::{Imagination, ModelView, ScoreKind, Seen};
use nn::frames::{frames_to_tensor, tensor_to_frames, tensor_to_unit_floats};
use world_model::model::WorldModel;
use world_model::rollout::Rollout;

use crate::EngineError;
use crate::decide::{decide, record_chunk};
use crate::error::judged;
use crate::start::{Begin, BranchOut, Setup, Start, Timing, Track, Trajectory, push, still_active};
use harness::policy::Policy;

/// The world-model branch of one batch. `start` is borrowed: its episodes are
/// still at their reset states (only the simulator branch, which takes it by
/// value, steps them).
///
/// # Errors
/// A policy error or non-finite generated latents, naming the policy and steps.
pub fn wm_branch(
    policy: &dyn Policy,
    start: &Start,
    s: &Setup,
    wm: &WorldModel,
    timing: &mut Timing,
) -> Result<BranchOut, EngineError> {
    let Begin { name, n, size, kind, o, mut hist, mut rngs, mut track, mut rec } = start.begin(policy, s);
    let mut gen_rngs = generator_rngs(start, s.master_seed, &name);
    let judges = first_scores(start, s, (&name, &kind), &mut track)?;
    let f_max = wm.cfg.future;
    let (mut imagine, mut roll, (c, ls)) = begin(start, wm, size, timing);
    let mut steps = 0;
    let mut active: Vec<usize> = (0..n).collect();
    // With `start.trajectories`: each episode's executed actions.
    let mut executed: Vec<Vec<Vec<f32>>> = vec![Vec::new(); n];
    while steps < s.max_steps && !active.is_empty() {
        let (chunks, len) = decide(policy, &hist, &active, size, &mut rngs, s.max_steps - steps, timing)?;
        if start.trajectories {
            for (&i, chunk) in active.iter().zip(&chunks) {
                executed[i].extend(chunk[..len].iter().cloned());
            }
        }
        let tw = Instant::now();
        let a = active.len();
        let mut sub: Vec<Rng> = active.iter().map(|&i| gen_rngs[i].clone()).collect();
        let mut done = 0;
        while done < len {
            let f = f_max.min(len - done);
            let pred =
                roll.step(wm, f, |p, j| chunks[p][done + j].as_slice(), &mut sub).map_err(|source| {
                    EngineError::WorldModel {
                        policy: name.clone(),
                        first: steps + done,
                        end: steps + done + f,
                        source,
                    }
                })?; // [a, f, C, s, s]
            // Decode only the frames the policy will see (the chunk's last `o`): decoding
            // is the most expensive part of the branch. They are also the frames judged,
            // unless every generated frame is (`Setup::judge_every_frame`).
            let first_seen = len.saturating_sub(o).max(done).min(done + f) - done; // <= f
            let first = if s.judge_every_frame { 0 } else { first_seen };
            let m = f - first;
            let (mut frames, mut exact) = if m > 0 {
                let seen = pred.narrow(1, first, m).reshape([a * m, c, ls, ls]);
                let decoded = wm.decode(seen);
                let exact = s.float_frames.then(|| tensor_to_unit_floats(decoded.clone()));
                (tensor_to_frames(decoded), exact)
            } else {
                (Vec::new(), None)
            };
            for (p, &i) in active.iter().enumerate() {
                for j in 0..f {
                    imagine[i].advance(&chunks[p][done + j]);
                    if j >= first {
                        let fr = &mut frames[p * m + j - first];
                        imagine[i].to_observation(fr);
                        track[i].add(judged(judges[i].score(fr), &name, start.seeds[i])?, &kind);
                        if j >= first_seen {
                            let x = exact.as_mut().map(|e| std::mem::take(&mut e[p * m + j - first]));
                            let seen = Seen {
                                frame: std::mem::take(fr),
                                proprio: imagine[i].proprio(),
                                robot: imagine[i].robot(),
                                exact: x,
                                native: None,
                            };
                            push(&mut hist[i], seen, o);
                        }
                    }
                }
            }
            timing.frames += (a * f) as u64;
            done += f;
        }
        for (&i, r) in active.iter().zip(sub) {
            gen_rngs[i] = r;
            track[i].steps += len;
            // Scene checks of the chunk's last seen frame only (the row keeps the last).
            if let Some(f) = hist[i].back() {
                track[i].scene = judges[i].scene(&f.frame);
            }
        }
        record_chunk(&mut rec, &hist, &active);
        track.iter_mut().for_each(Track::end_chunk);
        steps += len;
        let next = still_active(&active, &track);
        if next.len() < active.len() && !next.is_empty() {
            let kept: Vec<usize> =
                active.iter().enumerate().filter(|(_, i)| next.contains(i)).map(|(p, _)| p).collect();
            roll.keep(&kept);
        }
        active = next;
        timing.world_model_s += tw.elapsed().as_secs_f64();
    }
    let (rows, episodes) = finish(start, (&name, &kind), &track, start.trajectories.then_some(executed));
    Ok(BranchOut { rows, frames: rec, episodes })
}

/// The world model's sampling noise of each episode: its own stream of (master seed,
/// policy, seed), apart from the policy's.
fn generator_rngs(start: &Start, master_seed: u64, name: &str) -> Vec<Rng> {
    start
        .seeds
        .iter()
        .map(|&sd| Rng::new(derive(master_seed, &[fnv1a(name), sd, fnv1a("world_model")])))
        .collect()
}

/// Each episode's world-model adaptor and the batch's rollout, started from the encoded
/// first frames (the history repeats them; the anchor is them). Returns the latents'
/// channels and side too.
fn begin(
    start: &Start,
    wm: &WorldModel,
    size: usize,
    timing: &mut Timing,
) -> (Vec<Box<dyn Imagination>>, Rollout, (usize, usize)) {
    let n = start.envs.len();
    let tw = Instant::now();
    let device = wm.device().clone();
    let k = wm.cfg.unet.history;
    let view = if wm.cfg.is_goal_free() { ModelView::GoalFree } else { ModelView::Observation };
    let imagine: Vec<Box<dyn Imagination>> = start.envs.iter().map(|e| e.imagination(view)).collect();
    let refs: Vec<&[u8]> = imagine.iter().map(|m| m.first_frame()).collect();
    let z0 = wm.encode(frames_to_tensor(&refs, size, &device)); // [n, C, s, s]
    let [_, c, ls, _] = z0.dims();
    // Latent histories and anchors (the first frame) of the active episodes, in `active`'s order.
    let anchor = z0.clone(); // [a, C, s, s]
    let roll = Rollout::new(z0.unsqueeze_dim::<5>(1).expand([n, k, c, ls, ls]), anchor); // [a, K, C, s, s]
    timing.world_model_s += tw.elapsed().as_secs_f64();
    (imagine, roll, (c, ls))
}

/// Every episode's judge (imagined frames can only be scored by a judge of frames), with
/// each track started on the judge's score of the first frame and its scene checks.
///
/// # Errors
/// A task without a judge of frames, or a judge's score that is not finite.
fn first_scores<'a>(
    start: &'a Start,
    s: &Setup,
    (name, kind): (&str, &ScoreKind),
    track: &mut [Track],
) -> Result<Vec<&'a dyn Judge>, EngineError> {
    // Imagined frames can only be scored by a judge of frames.
    let judges: Vec<&dyn Judge> = start
        .judges
        .iter()
        .map(|j| j.as_deref().ok_or_else(|| EngineError::NoJudge { task: s.task.name().to_string() }))
        .collect::<Result<_, _>>()?;
    for (((t, judge), f), &seed) in track.iter_mut().zip(&judges).zip(&start.first).zip(&start.seeds) {
        t.persist(judge.persist());
        t.add(judged(judge.score(&f.frame), name, seed)?, kind);
        t.scene = judge.scene(&f.frame);
    }
    Ok(judges)
}

/// The branch's rows and, when the episodes' `executed` actions were kept, their
/// trajectories (actions only: nothing imagined is exact), for replaying them in the
/// simulator.
fn finish(
    start: &Start,
    (name, kind): (&str, &ScoreKind),
    track: &[Track],
    executed: Option<Vec<Vec<Vec<f32>>>>,
) -> (Vec<EpisodeRow>, Vec<Trajectory>) {
    let n = track.len();
    let rows: Vec<_> = (0..n)
        .map(|i| {
            track[i].row(name, start.seeds[i], Branch::WorldModel, kind).with_state(&start.conditions[i])
        })
        .collect();
    // The imagined episodes' actions, for replaying them in the simulator (no frames,
    // states or raw scores: nothing here is exact).
    let episodes = match executed {
        Some(executed) => executed
            .into_iter()
            .zip(&rows)
            .enumerate()
            .map(|(i, (actions, row))| Trajectory {
                seed: start.seeds[i],
                actions,
                goal: start.goals[i],
                score: row.score,
                success: row.success,
                ..Trajectory::default()
            })
            .collect(),
        None => Vec::new(),
    };
    (rows, episodes)
}
