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
//!   is scored exactly at every step.
//!
//! Both branches draw the policy's sampling noise from clones of the same
//! per-episode stream, so they are matched pairs. All episodes advance in
//! lockstep (batched policy and world model); MuJoCo steps run on rayon. An
//! episode leaves the batch at the end of the action chunk in which it succeeded
//! (as gym-pusht terminates at success), in each branch by that branch's score.

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Result, anyhow, bail};
use burn::tensor::{Tensor, TensorData};
use harness::policy::{ActionChunk, Observation, Policy};
use harness::rng::Rng;
use harness::seed::{derive, fnv1a};
use mujoco_rs::prelude::MjModel;
use rayon::prelude::*;
use scenarios::pusht::frame_score::{FrameScorer, SceneCheck};
use scenarios::pusht::render::Rasterizer;
use scenarios::pusht::{PushTConfig, PushTEnv};
use world_model::data::tensor_to_frames;
use world_model::latents::normalise_action;
use world_model::model::WorldModel;

use super::results::{Branch, EpisodeRow};

/// Wall-clock split of a batch.
#[derive(Clone, Copy, Debug, Default)]
pub struct Timing {
    /// MuJoCo stepping and rendering.
    pub sim_s: f64,
    /// World-model prediction and decoding.
    pub world_model_s: f64,
    /// Policy inference (both branches).
    pub policy_s: f64,
    /// Frames the world model generated.
    pub frames: u64,
}

impl Timing {
    /// Adds another split.
    pub fn add(&mut self, o: &Timing) {
        self.sim_s += o.sim_s;
        self.world_model_s += o.world_model_s;
        self.policy_s += o.policy_s;
        self.frames += o.frames;
    }
}

/// What a rollout needs besides the policy.
pub struct Setup<'a> {
    /// Scenario.
    pub cfg: &'a PushTConfig,
    /// Compiled MuJoCo model.
    pub model: &'a Arc<MjModel>,
    /// Master seed of the policy noise.
    pub master_seed: u64,
    /// Control steps per episode.
    pub max_steps: usize,
}

/// Per-episode running score.
#[derive(Clone, Debug, Default)]
struct Track {
    best_reward: f64,
    max_cov: f64,
    last_cov: f64,
    /// Control steps executed (until success or the step limit).
    steps: usize,
    /// Score so far at the end of each action chunk (repeated after the episode ended,
    /// so every trace of a batch has the same length).
    trace: Vec<f64>,
    /// Scene checks of the last frame the policy saw.
    scene: Option<SceneCheck>,
}

impl Track {
    fn add(&mut self, cov: f64, success_cov: f64) {
        self.best_reward = self.best_reward.max((cov / success_cov).clamp(0.0, 1.0));
        self.max_cov = self.max_cov.max(cov);
        self.last_cov = cov;
    }

    fn end_chunk(&mut self) {
        self.trace.push((self.best_reward * 1e6).round() / 1e6);
    }
}

/// A frame and the agent position seen with it.
type Seen = (Vec<u8>, [f32; 2]);

/// What one MuJoCo episode returns per chunk: coverages, the last frames, scorer error sum.
type ChunkResult = Result<(Vec<f64>, Vec<Seen>, f64)>;

fn obs_of(hist: &VecDeque<Seen>, size: usize) -> Observation {
    Observation {
        frames: hist.iter().map(|(f, _)| f.clone()).collect(),
        agent_pos: hist.iter().map(|(_, p)| *p).collect(),
        size,
    }
}

fn push(hist: &mut VecDeque<Seen>, item: Seen, keep: usize) {
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

/// What both branches start from: environments reset to the seeds, their goals,
/// frame scorers, the first rendered frames and the policy noise streams.
pub struct Start {
    envs: Vec<PushTEnv>,
    goals: Vec<[f64; 3]>,
    scorers: Vec<FrameScorer>,
    first: Vec<Vec<u8>>,
    start_pos: Vec<[f32; 2]>,
    policy_rngs: Vec<Rng>,
    seeds: Vec<u64>,
    /// Keep the last frame of every action chunk (for filmstrips and GIFs).
    pub record: bool,
}

/// A branch's rows and, when recording, each episode's frames at the end of every
/// action chunk (the first frame first).
pub struct BranchOut {
    /// One row per episode.
    pub rows: Vec<EpisodeRow>,
    /// Recorded frames per episode (empty unless recording).
    pub frames: Vec<Vec<Vec<u8>>>,
}

impl Start {
    /// Resets one environment per seed.
    ///
    /// # Errors
    /// A diverging first physics step, naming the seed.
    pub fn new(policy: &str, seeds: &[u64], s: &Setup) -> Result<Self> {
        let raster = Rasterizer::new(s.cfg);
        let mut envs = Vec::with_capacity(seeds.len());
        for &seed in seeds {
            let mut env = PushTEnv::new(s.model.clone(), s.cfg);
            env.reset(seed)?;
            envs.push(env);
        }
        let scorers = envs.iter().map(|e| FrameScorer::new(s.cfg, &e.goal(), raster.size())).collect();
        Ok(Self {
            goals: envs.iter().map(|e| e.goal().to_array()).collect(),
            scorers,
            first: envs.iter().map(|e| raster.render(&e.state(), &e.goal())).collect(),
            start_pos: envs.iter().map(|e| e.state().agent.map(|v| v as f32)).collect(),
            policy_rngs: seeds
                .iter()
                .map(|&sd| Rng::new(derive(s.master_seed, &[fnv1a(policy), sd])))
                .collect(),
            seeds: seeds.to_vec(),
            record: false,
            envs,
        })
    }

    fn recording(&self) -> Vec<Vec<Vec<u8>>> {
        if self.record { self.first.iter().map(|f| vec![f.clone()]).collect() } else { Vec::new() }
    }

    fn histories(&self, o: usize) -> Vec<VecDeque<Seen>> {
        (0..self.envs.len())
            .map(|i| (0..o).map(|_| (self.first[i].clone(), self.start_pos[i])).collect())
            .collect()
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

/// Episodes still running: gym-pusht ends an episode at success, and so does each
/// branch here, at the end of the action chunk that reached it (its score, the best
/// reward so far, cannot change after that).
fn still_active(active: &[usize], track: &[Track]) -> Vec<usize> {
    active.iter().copied().filter(|&i| track[i].best_reward < 1.0).collect()
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
        let results: Vec<Option<ChunkResult>> = start
            .envs
            .par_iter_mut()
            .zip(chunk_of.par_iter())
            .zip(start.scorers.par_iter())
            .map(|((env, chunk), scorer)| {
                let chunk = (*chunk)?;
                let mut run = || {
                    let (mut covs, mut frames, mut err) = (Vec::with_capacity(len), Vec::new(), 0.0);
                    for (j, a) in chunk[..len].iter().enumerate() {
                        let sc = env.step([f64::from(a[0]), f64::from(a[1])])?;
                        covs.push(sc.coverage);
                        if j + o >= len {
                            let st = env.state();
                            let f = raster.render(&st, &env.goal());
                            err += (scorer.coverage(&f) - sc.coverage).abs();
                            frames.push((f, st.agent.map(|v| v as f32)));
                        }
                    }
                    Ok((covs, frames, err))
                };
                Some(run())
            })
            .collect();
        for (i, r) in results.into_iter().enumerate() {
            let Some(r) = r else { continue };
            let (covs, frames, err) = r?;
            covs.iter().for_each(|&cv| track[i].add(cv, thr));
            track[i].steps += len;
            scorer_err[i].0 += err;
            scorer_err[i].1 += frames.len();
            if let Some((f, _)) = frames.last() {
                track[i].scene = Some(start.scorers[i].scene(f));
            }
            frames.into_iter().for_each(|f| push(&mut hist[i], f, o));
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
    Ok(BranchOut { rows, frames: rec })
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
    let refs: Vec<&[u8]> = start.first.iter().map(Vec::as_slice).collect();
    let z0 = wm.encode(policies::diffusion::frames_to_tensor(&refs, size, &device)); // [n, C, s, s]
    let [_, c, ls, _] = z0.dims();
    // Latent histories and anchors (the first frame) of the active episodes, in `active`'s order.
    let mut anchor = z0.clone(); // [a, C, s, s]
    let mut zh = z0.unsqueeze_dim::<5>(1).expand([n, k, c, ls, ls]); // [a, K, C, s, s]
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
            let acts: Vec<f32> = chunks
                .iter()
                .flat_map(|ch| ch[done..done + f].iter().flat_map(|a| a.map(normalise_action)))
                .collect();
            let act = Tensor::<3>::from_data(TensorData::new(acts, [a, f, 2]), &device);
            let pred = wm.predict(zh.clone(), anchor.clone(), act, &mut sub); // [a, f, C, s, s]
            let check: f32 = pred.clone().abs().sum().into_scalar();
            if !check.is_finite() {
                bail!("world model produced non-finite latents for policy {name} at step {}", steps + done);
            }
            // Decode only the frames the policy will see (the chunk's last `o`): decoding
            // is the most expensive part of the branch. They are also the frames scored.
            let first_seen = len.saturating_sub(o).max(done).min(done + f) - done;
            if first_seen < f {
                let m = f - first_seen;
                let seen = pred.clone().narrow(1, first_seen, m).reshape([a * m, c, ls, ls]);
                let frames = tensor_to_frames(wm.decode(seen));
                for (p, &i) in active.iter().enumerate() {
                    for j in 0..m {
                        let fr = &frames[p * m + j];
                        track[i].add(start.scorers[i].coverage(fr), thr);
                        push(&mut hist[i], (fr.clone(), chunks[p][done + first_seen + j]), o);
                    }
                }
            }
            zh = Tensor::cat(vec![zh, pred], 1).narrow(1, f, k);
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
            zh = Tensor::cat(kept.iter().map(|&p| zh.clone().narrow(0, p, 1)).collect(), 0);
            anchor = Tensor::cat(kept.iter().map(|&p| anchor.clone().narrow(0, p, 1)).collect(), 0);
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
    Ok(BranchOut { rows, frames: rec })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn succeeded_episodes_leave_the_batch_and_keep_their_trace() {
        let mut track = vec![Track::default(); 3];
        // Success coverage 0.95: coverage 0.95 gives reward 1 (ends), 0.5 gives 0.526.
        track[0].add(0.5, 0.95);
        track[1].add(0.95, 0.95);
        track[2].add(0.2, 0.95);
        assert_eq!(still_active(&[0, 1, 2], &track), vec![0, 2]);
        // A finished episode is not revived, and its trace keeps the batch's length.
        assert_eq!(still_active(&[0, 2], &track), vec![0, 2]);
        track.iter_mut().for_each(Track::end_chunk);
        track.iter_mut().for_each(Track::end_chunk);
        assert_eq!(track[1].trace, vec![1.0, 1.0]);
        assert_eq!(track[0].trace, vec![0.526316, 0.526316]);
    }
}
