//! One policy, a batch of episode seeds, two branches from the same initial state.
//!
//! - **MuJoCo**: the policy sees rendered frames and the real agent position; the
//!   score is exact (polygon coverage of the simulator state).
//! - **World model**: the history starts as the first rendered frame repeated 4×;
//!   each action chunk is imagined in one-pass chunks of F frames; the policy sees
//!   only decoded imagined frames, with the last commanded action standing in for
//!   the agent position (as in DriftWorld's evaluation); frames are scored by
//!   [`FrameScorer`] against the known goal.
//!
//! Both branches draw the policy's sampling noise from clones of the same
//! per-episode stream, so they are matched pairs. All episodes advance in
//! lockstep (batched policy and world model); MuJoCo steps run on rayon.

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
use scenarios::pusht::frame_score::FrameScorer;
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

/// What a rollout needs besides the policy.
pub struct Setup<'a> {
    /// Scenario.
    pub cfg: &'a PushTConfig,
    /// Compiled MuJoCo model.
    pub model: &'a Arc<MjModel>,
    /// The world model.
    pub wm: &'a WorldModel,
    /// Master seed of the policy noise.
    pub master_seed: u64,
    /// Control steps per episode.
    pub max_steps: usize,
}

/// Per-episode running score.
#[derive(Clone, Copy, Debug, Default)]
struct Track {
    best_reward: f64,
    max_cov: f64,
    last_cov: f64,
}

impl Track {
    fn add(&mut self, cov: f64, success_cov: f64) {
        self.best_reward = self.best_reward.max((cov / success_cov).clamp(0.0, 1.0));
        self.max_cov = self.max_cov.max(cov);
        self.last_cov = cov;
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

/// Runs both branches for `seeds`; returns one row per (seed, branch), MuJoCo first.
///
/// # Errors
/// A policy error (NaN output, bad input) or a non-finite world-model frame, naming
/// the policy; a diverging simulation, naming the seed and step.
pub fn run_batch(
    policy: &dyn Policy,
    seeds: &[u64],
    s: &Setup,
    timing: &mut Timing,
) -> Result<Vec<EpisodeRow>> {
    let (cfg, wm) = (s.cfg, s.wm);
    let name = policy.name().to_string();
    let n = seeds.len();
    let raster = Rasterizer::new(cfg);
    let size = raster.size();
    let o = policy.obs_horizon().max(1);
    let thr = cfg.task.success_coverage;
    let t0 = Instant::now();
    let mut envs: Vec<PushTEnv> = Vec::with_capacity(n);
    for &seed in seeds {
        let mut env = PushTEnv::new(s.model.clone(), cfg);
        env.reset(seed)?;
        envs.push(env);
    }
    let goals: Vec<_> = envs.iter().map(PushTEnv::goal).collect();
    let scorers: Vec<FrameScorer> = goals.iter().map(|g| FrameScorer::new(cfg, g, size)).collect();
    let first: Vec<Vec<u8>> = envs.iter().map(|e| raster.render(&e.state(), &e.goal())).collect();
    let start_pos: Vec<[f32; 2]> = envs.iter().map(|e| e.state().agent.map(|v| v as f32)).collect();
    let init = |i: usize| -> VecDeque<Seen> { (0..o).map(|_| (first[i].clone(), start_pos[i])).collect() };
    let mut sim_hist: Vec<_> = (0..n).map(init).collect();
    let mut wm_hist: Vec<_> = (0..n).map(init).collect();
    let mut sim_rngs: Vec<Rng> =
        seeds.iter().map(|&sd| Rng::new(derive(s.master_seed, &[fnv1a(&name), sd]))).collect();
    let mut wm_rngs = sim_rngs.clone();
    let mut gen_rngs: Vec<Rng> = seeds
        .iter()
        .map(|&sd| Rng::new(derive(s.master_seed, &[fnv1a(&name), sd, fnv1a("world_model")])))
        .collect();
    let mut sim_track = vec![Track::default(); n];
    let mut wm_track = vec![Track::default(); n];
    let mut scorer_err = vec![(0.0f64, 0usize); n];
    for i in 0..n {
        let c = envs[i].score().coverage;
        sim_track[i].add(c, thr);
        wm_track[i].add(scorers[i].coverage(&first[i]), thr);
    }
    let device = wm.device().clone();
    let k = wm.cfg.unet.history;
    let refs: Vec<&[u8]> = first.iter().map(Vec::as_slice).collect();
    let first_t = policies::diffusion::frames_to_tensor(&refs, size, &device); // [n, 3, H, W]
    let z0 = wm.encode(first_t); // [n, C, s, s]
    let [_, c, ls, _] = z0.dims();
    let mut zh = z0.unsqueeze_dim::<5>(1).expand([n, k, c, ls, ls]); // [n, K, C, s, s]
    timing.sim_s += t0.elapsed().as_secs_f64();
    let mut steps = 0;
    while steps < s.max_steps {
        // MuJoCo branch.
        let tp = Instant::now();
        let obs: Vec<Observation> = sim_hist.iter().map(|h| obs_of(h, size)).collect();
        let chunks: Vec<ActionChunk> = policy.act(&obs, &mut sim_rngs).map_err(|e| anyhow!(e))?;
        timing.policy_s += tp.elapsed().as_secs_f64();
        let len = chunks.iter().map(Vec::len).min().unwrap_or(0).min(s.max_steps - steps);
        if len == 0 {
            bail!("policy {name} returned an empty action chunk");
        }
        let ts = Instant::now();
        let results: Vec<ChunkResult> = envs
            .par_iter_mut()
            .zip(chunks.par_iter())
            .zip(scorers.par_iter())
            .map(|((env, chunk), scorer)| {
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
            })
            .collect();
        for (i, r) in results.into_iter().enumerate() {
            let (covs, frames, err) = r?;
            covs.iter().for_each(|&cv| sim_track[i].add(cv, thr));
            scorer_err[i].0 += err;
            scorer_err[i].1 += frames.len();
            frames.into_iter().for_each(|f| push(&mut sim_hist[i], f, o));
        }
        timing.sim_s += ts.elapsed().as_secs_f64();
        // World-model branch.
        let tp = Instant::now();
        let obs: Vec<Observation> = wm_hist.iter().map(|h| obs_of(h, size)).collect();
        let chunks: Vec<ActionChunk> = policy.act(&obs, &mut wm_rngs).map_err(|e| anyhow!(e))?;
        timing.policy_s += tp.elapsed().as_secs_f64();
        let tw = Instant::now();
        let f_max = wm.cfg.future;
        let mut done = 0;
        while done < len {
            let f = f_max.min(len - done);
            let acts: Vec<f32> = chunks
                .iter()
                .flat_map(|ch| ch[done..done + f].iter().flat_map(|a| a.map(normalise_action)))
                .collect();
            let act = Tensor::<3>::from_data(TensorData::new(acts, [n, f, 2]), &device);
            let pred = wm.predict(zh.clone(), act, &mut gen_rngs); // [n, f, C, s, s]
            let check: f32 = pred.clone().abs().sum().into_scalar();
            if !check.is_finite() {
                bail!("world model produced non-finite latents for policy {name} at step {}", steps + done);
            }
            let frames = tensor_to_frames(wm.decode(pred.clone().reshape([n * f, c, ls, ls])));
            zh = Tensor::cat(vec![zh, pred], 1).narrow(1, f, k);
            for i in 0..n {
                for j in 0..f {
                    let fr = &frames[i * f + j];
                    wm_track[i].add(scorers[i].coverage(fr), thr);
                    if done + j + o >= len {
                        push(&mut wm_hist[i], (fr.clone(), chunks[i][done + j]), o);
                    }
                }
            }
            timing.frames += (n * f) as u64;
            done += f;
        }
        timing.world_model_s += tw.elapsed().as_secs_f64();
        steps += len;
    }
    let mut rows = Vec::with_capacity(2 * n);
    for i in 0..n {
        let g = goals[i].to_array();
        let st = envs[i].state();
        let (st_, wt) = (sim_track[i], wm_track[i]);
        let err = scorer_err[i].0 / scorer_err[i].1.max(1) as f64;
        rows.push(
            EpisodeRow::new(
                &name,
                seeds[i],
                Branch::Sim,
                st_.best_reward,
                st_.max_cov,
                st_.last_cov,
                thr,
                steps,
            )
            .with_poses(Some(st.block.to_array()), g)
            .with_scorer_error(Some(err)),
        );
        rows.push(
            EpisodeRow::new(
                &name,
                seeds[i],
                Branch::WorldModel,
                wt.best_reward,
                wt.max_cov,
                wt.last_cov,
                thr,
                steps,
            )
            .with_poses(None, g),
        );
    }
    Ok(rows)
}
