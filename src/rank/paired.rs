//! One policy, a batch of episode seeds, two branches from the same initial state.
//!
//! - **MuJoCo**: the policy sees rendered frames and the real agent position; the
//!   score is exact (polygon coverage of the simulator state).
//! - **World model**: the history starts as the first rendered frame repeated 4×;
//!   each action chunk is imagined in one-pass chunks of F frames; the policy sees
//!   only decoded imagined frames, with the last commanded action standing in for
//!   the agent position (as in DriftWorld's evaluation). Only the frames the
//!   policy sees (the last `obs_horizon` of each chunk) are decoded to pixels, and
//!   those are scored by [`FrameScorer`] against the known goal; the MuJoCo branch
//!   is scored exactly at every step. A goal-free world model (`train world-model
//!   --goal-free`) starts from the first frame rendered without the goal, and each
//!   decoded frame gets the episode's goal drawn back (`FrameScorer::draw_goal`)
//!   before the policy, the scorer or a recording sees it.
//!
//! Both branches draw the policy's sampling noise from clones of the same
//! per-episode stream, so they are matched pairs. All episodes advance in
//! lockstep (batched policy and world model); MuJoCo steps run on rayon. An
//! episode leaves the batch at the end of the action chunk in which it succeeded
//! (as gym-pusht terminates at success), in each branch by that branch's score.

use std::collections::VecDeque;
use std::time::Instant;

use anyhow::{Result, anyhow, bail};
use harness::policy::{ActionChunk, Observation, Policy};
use harness::rng::Rng;
use harness::seed::{derive, fnv1a};
use rayon::prelude::*;
use scenarios::pusht::render::Rasterizer;
use scenarios::pusht::rollout::{Episode, StepRow};
use world_model::data::tensor_to_frames;
use world_model::model::WorldModel;
use world_model::rollout::Rollout;

use super::results::{Branch, EpisodeRow, WithScene};
pub use super::start::{BranchOut, Setup, Start, Timing};
use super::start::{Seen, Track, still_active};

/// What one MuJoCo episode returns per chunk.
#[derive(Default)]
struct ChunkOut {
    /// Coverage after each executed action.
    covs: Vec<f64>,
    /// The frames the policy will see (the chunk's last `obs_horizon`).
    seen: Vec<Seen>,
    /// Sum of the frame scorer's absolute coverage errors on `seen`.
    err: f64,
    /// With [`Start::trajectories`]: each step's observation before the action, and its row.
    steps: Vec<(Vec<u8>, StepRow)>,
}

/// The observation of an episode's last frames (oldest first) and agent positions.
pub(crate) fn obs_of(hist: &VecDeque<Seen>, size: usize) -> Observation {
    Observation {
        frames: hist.iter().map(|(f, _)| f.clone()).collect(),
        agent_pos: hist.iter().map(|(_, p)| *p).collect(),
        size,
    }
}

/// Appends `item` and keeps the newest `keep` items.
pub(crate) fn push<T>(hist: &mut VecDeque<T>, item: T, keep: usize) {
    hist.push_back(item);
    while hist.len() > keep {
        hist.pop_front();
    }
}

/// Appends every episode's newest frame to its recording (an ended episode repeats its
/// last one, so both branches' strips stay aligned); a no-op when not recording.
fn record_chunk(rec: &mut [Vec<Vec<u8>>], hist: &[VecDeque<Seen>]) {
    for (r, h) in rec.iter_mut().zip(hist) {
        if let Some(last) = h.back() {
            r.push(last.0.clone());
        }
    }
}

/// One batched decision for the `active` episodes: their chunks (in `active`'s order)
/// and how many actions to execute (the shortest chunk, at most `left`). Each
/// episode keeps its own noise stream, whichever others are still running.
fn decide(
    policy: &dyn Policy,
    hist: &[VecDeque<Seen>],
    active: &[usize],
    size: usize,
    rngs: &mut [Rng],
    left: usize,
    timing: &mut Timing,
) -> Result<(Vec<ActionChunk>, usize)> {
    let tp = Instant::now();
    let obs: Vec<Observation> = active.iter().map(|&i| obs_of(&hist[i], size)).collect();
    let mut sub: Vec<Rng> = active.iter().map(|&i| rngs[i].clone()).collect();
    let chunks = policy.act(&obs, &mut sub).map_err(|e| anyhow!(e))?;
    for (&i, r) in active.iter().zip(sub) {
        rngs[i] = r;
    }
    timing.policy_s += tp.elapsed().as_secs_f64();
    let len = chunks.iter().map(Vec::len).min().unwrap_or(0).min(left);
    if len == 0 || chunks.len() != active.len() {
        bail!("policy {} returned an empty action chunk or too few chunks", policy.name());
    }
    Ok((chunks, len))
}

/// The MuJoCo branch: real frames, real agent positions, exact scores.
///
/// # Errors
/// A policy error or a diverging simulation.
pub fn sim_branch(
    policy: &dyn Policy,
    mut start: Start,
    s: &Setup,
    timing: &mut Timing,
) -> Result<BranchOut> {
    let name = policy.name().to_string();
    let n = start.envs.len();
    let raster = Rasterizer::new(s.cfg);
    let size = raster.size();
    let o = policy.obs_horizon().max(1);
    let thr = s.cfg.task.success_coverage;
    let mut hist = start.histories(o);
    let mut rngs = start.policy_rngs.clone();
    let mut track = vec![Track::default(); n];
    let mut scorer_err = vec![(0.0f64, 0usize); n];
    let mut rec = start.recording();
    let trajectories = start.trajectories;
    let mut traj: Vec<Vec<(Vec<u8>, StepRow)>> = vec![Vec::new(); n];
    for (((t, env), sc), f) in track.iter_mut().zip(&start.envs).zip(&start.scorers).zip(&start.first) {
        t.add(env.score().coverage, thr);
        t.scene = Some(sc.scene(f));
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
        let results: Vec<Option<Result<ChunkOut>>> = start
            .envs
            .par_iter_mut()
            .zip(chunk_of.par_iter())
            .zip(start.scorers.par_iter())
            .map(|((env, chunk), scorer)| {
                let chunk = (*chunk)?;
                let mut run = || -> Result<ChunkOut> {
                    let mut out = ChunkOut { covs: Vec::with_capacity(len), ..ChunkOut::default() };
                    for (j, a) in chunk[..len].iter().enumerate() {
                        let before = trajectories.then(|| env.state());
                        let action = [f64::from(a[0]), f64::from(a[1])];
                        let sc = env.step(action)?;
                        out.covs.push(sc.coverage);
                        if let Some(b) = before {
                            let step = (steps + j) as u32;
                            let row = StepRow {
                                step,
                                agent: b.agent,
                                block: b.block,
                                action,
                                coverage: sc.coverage,
                            };
                            out.steps.push((raster.render(&b, &env.goal()), row));
                        }
                        if j + o >= len {
                            let st = env.state();
                            let f = raster.render(&st, &env.goal());
                            out.err += (scorer.coverage(&f) - sc.coverage).abs();
                            out.seen.push((f, st.agent.map(|v| v as f32)));
                        }
                    }
                    Ok(out)
                };
                Some(run())
            })
            .collect();
        for (i, r) in results.into_iter().enumerate() {
            let Some(r) = r else { continue };
            let out = r?;
            out.covs.iter().for_each(|&cv| track[i].add(cv, thr));
            track[i].steps += len;
            scorer_err[i].0 += out.err;
            scorer_err[i].1 += out.seen.len();
            if let Some((f, _)) = out.seen.last() {
                track[i].scene = Some(start.scorers[i].scene(f));
            }
            out.seen.into_iter().for_each(|f| push(&mut hist[i], f, o));
            traj[i].extend(out.steps);
        }
        record_chunk(&mut rec, &hist);
        track.iter_mut().for_each(Track::end_chunk);
        timing.sim_s += ts.elapsed().as_secs_f64();
        steps += len;
        active = still_active(&active, &track);
    }
    let rows = (0..n)
        .map(|i| {
            let t = &track[i];
            let err = scorer_err[i].0 / scorer_err[i].1.max(1) as f64;
            EpisodeRow::new(
                &name,
                start.seeds[i],
                Branch::Sim,
                t.best_reward,
                t.max_cov,
                t.last_cov,
                thr,
                t.steps,
            )
            .with_poses(Some(start.envs[i].state().block.to_array()), start.goals[i])
            .with_scorer_error(Some(err))
            .with_trace(t.trace.clone())
            .with_scene(t.scene)
        })
        .collect();
    let episodes = if trajectories { finish_episodes(&start, &track, traj, &raster) } else { Vec::new() };
    Ok(BranchOut { rows, frames: rec, episodes })
}

/// The recorded steps as whole episodes (observations before each action plus the
/// final one, as `collect` writes them).
fn finish_episodes(
    start: &Start,
    track: &[Track],
    traj: Vec<Vec<(Vec<u8>, StepRow)>>,
    raster: &Rasterizer,
) -> Vec<Episode> {
    let mut out = Vec::with_capacity(traj.len());
    for (i, steps) in traj.into_iter().enumerate() {
        let env = &start.envs[i];
        let (mut frames, rows): (Vec<Vec<u8>>, Vec<StepRow>) = steps.into_iter().unzip();
        frames.push(raster.render(&env.state(), &env.goal()));
        let success = rows.iter().any(|r| r.coverage > env.config().task.success_coverage);
        let (seed, goal, score) = (start.seeds[i], env.goal(), track[i].best_reward);
        out.push(Episode { seed, goal, rows, frames, score, success });
    }
    out
}

/// The world-model branch: imagined frames only, scored from frames.
///
/// # Errors
/// A policy error or non-finite generated latents, naming the policy.
pub fn wm_branch(
    policy: &dyn Policy,
    start: &Start,
    s: &Setup,
    wm: &WorldModel,
    timing: &mut Timing,
) -> Result<BranchOut> {
    let name = policy.name().to_string();
    let n = start.envs.len();
    let size = Rasterizer::new(s.cfg).size();
    let o = policy.obs_horizon().max(1);
    let thr = s.cfg.task.success_coverage;
    let mut hist = start.histories(o);
    let mut rngs = start.policy_rngs.clone();
    let mut gen_rngs: Vec<Rng> = start
        .seeds
        .iter()
        .map(|&sd| Rng::new(derive(s.master_seed, &[fnv1a(&name), sd, fnv1a("world_model")])))
        .collect();
    let mut track = vec![Track::default(); n];
    let mut rec = start.recording();
    for ((t, sc), f) in track.iter_mut().zip(&start.scorers).zip(&start.first) {
        t.add(sc.coverage(f), thr);
        t.scene = Some(sc.scene(f));
    }
    let tw = Instant::now();
    let device = wm.device().clone();
    let (k, f_max) = (wm.cfg.unet.history, wm.cfg.future);
    let goal_free = wm.cfg.is_goal_free();
    // A borrowed `Start`'s environments are still at their reset states (only the
    // MuJoCo branch, which takes it by value, steps them).
    let without_goal: Vec<Vec<u8>> = if goal_free {
        let raster = Rasterizer::new(s.cfg);
        start.envs.iter().map(|e| raster.render_without_goal(&e.state())).collect()
    } else {
        Vec::new()
    };
    let firsts = if goal_free { &without_goal } else { &start.first };
    let refs: Vec<&[u8]> = firsts.iter().map(Vec::as_slice).collect();
    let z0 = wm.encode(policies::diffusion::frames_to_tensor(&refs, size, &device)); // [n, C, s, s]
    let [_, c, ls, _] = z0.dims();
    // Latent histories and anchors (the first frame) of the active episodes, in `active`'s order.
    let anchor = z0.clone(); // [a, C, s, s]
    let mut roll = Rollout::new(z0.unsqueeze_dim::<5>(1).expand([n, k, c, ls, ls]), anchor); // [a, K, C, s, s]
    timing.world_model_s += tw.elapsed().as_secs_f64();
    let mut steps = 0;
    let mut active: Vec<usize> = (0..n).collect();
    while steps < s.max_steps && !active.is_empty() {
        let (chunks, len) = decide(policy, &hist, &active, size, &mut rngs, s.max_steps - steps, timing)?;
        let tw = Instant::now();
        let a = active.len();
        let mut sub: Vec<Rng> = active.iter().map(|&i| gen_rngs[i].clone()).collect();
        let mut done = 0;
        while done < len {
            let f = f_max.min(len - done);
            let pred = roll.step(wm, f, |p, j| chunks[p][done + j], &mut sub).map_err(|e| {
                anyhow::Error::new(e).context(format!(
                    "policy {name}, episode steps {}..{}",
                    steps + done,
                    steps + done + f
                ))
            })?; // [a, f, C, s, s]
            // Decode only the frames the policy will see (the chunk's last `o`): decoding
            // is the most expensive part of the branch. They are also the frames scored.
            let first_seen = len.saturating_sub(o).max(done).min(done + f) - done;
            if first_seen < f {
                let m = f - first_seen;
                let seen = pred.clone().narrow(1, first_seen, m).reshape([a * m, c, ls, ls]);
                let mut frames = tensor_to_frames(wm.decode(seen));
                for (p, &i) in active.iter().enumerate() {
                    for j in 0..m {
                        let fr = &mut frames[p * m + j];
                        if goal_free {
                            start.scorers[i].draw_goal(fr);
                        }
                        track[i].add(start.scorers[i].coverage(fr), thr);
                        push(&mut hist[i], (fr.clone(), chunks[p][done + first_seen + j]), o);
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
            if let Some((f, _)) = hist[i].back() {
                track[i].scene = Some(start.scorers[i].scene(f));
            }
        }
        record_chunk(&mut rec, &hist);
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
    let rows = (0..n)
        .map(|i| {
            let t = &track[i];
            EpisodeRow::new(
                &name,
                start.seeds[i],
                Branch::WorldModel,
                t.best_reward,
                t.max_cov,
                t.last_cov,
                thr,
                t.steps,
            )
            .with_poses(None, start.goals[i])
            .with_trace(t.trace.clone())
            .with_scene(t.scene)
        })
        .collect();
    Ok(BranchOut { rows, frames: rec, episodes: Vec::new() })
}
