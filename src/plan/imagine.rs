//! Imagining a decision's proposals: in the world model (batched, one-pass
//! chunks, from the last real frames) or in MuJoCo (a copy of the true state per
//! proposal). Both return one cost per proposal ([`GoalDistance`] of the last
//! imagined frame; `None` where that frame shows no block), in the decision's
//! episode-major proposal order.
//!
//! [`GoalDistance`]: scenarios::pusht::plan_cost::GoalDistance

use anyhow::{Result, anyhow};
use burn::tensor::Tensor;
use harness::policy::ActionChunk;
use harness::rng::Rng;
use harness::seed::{derive, fnv1a};
use rayon::prelude::*;
use scenarios::pusht::PushTEnv;
use scenarios::pusht::render::Rasterizer;
use world_model::data::tensor_to_frames;
use world_model::model::WorldModel;
use world_model::rollout::Rollout;

use super::state::{Ctx, Live};

/// Each proposal's cost and last imagined frame (with the goal), in proposal order.
pub struct Imagined {
    pub costs: Vec<Option<f64>>,
    pub frames: Vec<Vec<u8>>,
}

/// One decision of a batch: who is active and what they proposed.
pub struct Decision<'a> {
    pub live: &'a [Live],
    /// Indices into `live`, in proposal order.
    pub active: &'a [usize],
    /// `active.len() * k` proposals, episode-major.
    pub chunks: &'a [ActionChunk],
    /// Proposals per episode.
    pub k: usize,
    /// The decision's index in its episodes (0 first).
    pub index: u64,
}

/// Each proposal's first `ctx.imagine` actions stepped in MuJoCo from its episode's
/// current state (velocities of the block are not carried over: the Push-T block is
/// damped to quasi-static motion, see `scenarios::pusht::physics`).
///
/// # Errors
/// A diverging imagined simulation, naming the episode seed.
pub fn in_simulator(ctx: &Ctx, d: &Decision, raster: &Rasterizer) -> Result<Imagined> {
    // The episode of each proposal, in proposal order.
    let owner: Vec<usize> = d.active.iter().flat_map(|&i| std::iter::repeat_n(i, d.k)).collect();
    let out: Vec<(Option<f64>, Vec<u8>)> = ctx.pool.install(|| {
        owner
            .par_iter()
            .enumerate()
            .map(|(q, &i)| {
                let l = &d.live[i];
                let mut env = PushTEnv::new(ctx.model.clone(), ctx.cfg);
                env.set_state(&l.env.state());
                env.set_goal(l.env.goal());
                for a in &d.chunks[q][..ctx.imagine] {
                    env.step([f64::from(a[0]), f64::from(a[1])]).map_err(|e| {
                        anyhow::anyhow!("imagining a proposal of episode {}: {e}", l.row.seed)
                    })?;
                }
                let frame = raster.render(&env.state(), &env.goal());
                Ok((l.cost.cost(&frame), frame))
            })
            .collect::<Result<_>>()
    })?;
    let (costs, frames) = out.into_iter().unzip();
    Ok(Imagined { costs, frames })
}

/// Each proposal's first `ctx.imagine` actions rolled out in the world model from its
/// episode's last real frames; the last imagined frame is decoded (the goal drawn
/// back for a goal-free model) and scored.
///
/// # Errors
/// Non-finite latents, naming the policy and the decision.
pub fn in_world_model(ctx: &Ctx, wm: &WorldModel, d: &Decision, size: usize) -> Result<Imagined> {
    let device = wm.device().clone();
    let (hist, f_max) = (wm.cfg.unet.history, wm.cfg.future);
    let (a, k) = (d.active.len(), d.k);
    let b = a * k;
    let name = ctx.policy.name();
    // Encode each active episode's history and first frame: [a (hist + 1), 3, S, S].
    let frames: Vec<&[u8]> = d
        .active
        .iter()
        .flat_map(|&i| d.live[i].wm_hist.iter().chain(std::iter::once(&d.live[i].wm_first)))
        .map(Vec::as_slice)
        .collect();
    let z = wm.encode(policies::diffusion::frames_to_tensor(&frames, size, &device)); // [a (K+1), C, s, s]
    let [_, c, ls, _] = z.dims();
    let z = z.reshape([a, hist + 1, c, ls, ls]);
    // Every proposal of an episode starts from the same latents: [a, k, ...] -> [b, ...].
    let per = |t: Tensor<5>, n: usize| -> Tensor<5> {
        t.unsqueeze_dim::<6>(1).expand([a, k, n, c, ls, ls]).reshape([b, n, c, ls, ls])
    };
    let zh = per(z.clone().narrow(1, 0, hist), hist); // [b, K, C, s, s]
    let anchor = per(z.narrow(1, hist, 1), 1).reshape([b, c, ls, ls]); // [b, C, s, s]
    let mut roll = Rollout::new(zh, anchor);
    let mut rngs: Vec<Rng> = d
        .active
        .iter()
        .flat_map(|&i| (0..k as u64).map(move |j| (i, j)))
        .map(|(i, j)| {
            let seed = d.live[i].row.seed;
            Rng::new(derive(ctx.master_seed, &[fnv1a(name), seed, d.index, j, fnv1a("world_model")]))
        })
        .collect();
    let mut last = None;
    while roll.generated() < ctx.imagine {
        let (done, f) = (roll.generated(), f_max.min(ctx.imagine - roll.generated()));
        let pred = roll
            .step(wm, f, |q, j| d.chunks[q][done + j].as_slice(), &mut rngs)
            .map_err(|e| anyhow!("imagining proposals of policy {name} at decision {}: {e}", d.index))?; // [b, f, C, s, s]
        last = Some(pred.narrow(1, f - 1, 1).reshape([b, c, ls, ls]));
    }
    let Some(last) = last else { return Ok(Imagined { costs: vec![None; b], frames: vec![Vec::new(); b] }) };
    let mut frames = tensor_to_frames(wm.decode(last));
    let goal_free = wm.cfg.is_goal_free();
    let costs = frames
        .iter_mut()
        .enumerate()
        .map(|(q, fr)| {
            let l = &d.live[d.active[q / k]];
            if goal_free {
                l.scorer.draw_goal(fr);
            }
            l.cost.cost(fr)
        })
        .collect();
    Ok(Imagined { costs, frames })
}
