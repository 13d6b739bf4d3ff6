//! Imagining a decision's proposals: in the world model (batched, one-pass
//! chunks, from the last real frames) or in the simulator (a copy of the true state
//! per proposal). Both return one cost per proposal (the episode's [`PlanCost`] of
//! the last imagined frame; `None` where that frame shows too little), in the
//! decision's episode-major proposal order.
//!
//! [`PlanCost`]: harness::task::PlanCost

use burn::tensor::Tensor;
use harness::policy::ActionChunk;
use harness::rng::Rng;
use harness::seed::{derive, fnv1a};
use harness::task::{Env, PlanCost};
use nn::frames::{frames_to_tensor, tensor_to_frames};
use rayon::prelude::*;
use world_model::model::WorldModel;
use world_model::rollout::Rollout;

use super::state::{Live, PlanCtx};
use crate::EngineError;

/// Each proposal's cost and last imagined frame (in the policy's view), in proposal order.
pub(super) struct Imagined {
    pub(super) costs: Vec<Option<f64>>,
    pub(super) frames: Vec<Vec<u8>>,
}

/// One decision of a batch: who is active and what they proposed.
pub(super) struct Decision<'a> {
    pub(super) live: &'a [Live],
    /// Indices into `live`, in proposal order.
    pub(super) active: &'a [usize],
    /// `active.len() * k` proposals, episode-major.
    pub(super) chunks: &'a [ActionChunk],
    /// Proposals per episode.
    pub(super) k: usize,
    /// The decision's index in its episodes (0 first).
    pub(super) index: u64,
}

/// Each proposal's first `ctx.imagine` actions stepped in a copy of its episode
/// ([`Env::fork`], made here in proposal order) from the current state.
///
/// # Errors
/// A task that cannot copy its episodes, or a diverging imagined simulation, naming
/// the episode seed.
pub(super) fn in_simulator(ctx: &PlanCtx, d: &Decision) -> Result<Imagined, EngineError> {
    let mut copies: Vec<(Box<dyn Env>, &dyn PlanCost)> = Vec::with_capacity(d.active.len() * d.k);
    for &i in d.active {
        let l = &d.live[i];
        for _ in 0..d.k {
            let copy =
                l.env.fork().ok_or_else(|| EngineError::CannotPlan { task: ctx.task.name().to_string() })?;
            copies.push((copy, l.cost.as_ref()));
        }
    }
    let (chunks, n) = (d.chunks, ctx.imagine);
    let out: Vec<(Option<f64>, Vec<u8>)> = ctx.pool.install(|| {
        copies
            .into_par_iter()
            .enumerate()
            .map(|(q, (mut env, cost))| {
                for a in &chunks[q][..n] {
                    env.step(a).map_err(|source| EngineError::Imagining { seed: env.seed(), source })?;
                }
                let frame = env.observe().frame;
                Ok((cost.cost(&frame), frame))
            })
            .collect::<Result<_, EngineError>>()
    })?;
    let (costs, frames) = out.into_iter().unzip();
    Ok(Imagined { costs, frames })
}

/// Each proposal's first `ctx.imagine` actions rolled out in the world model from its
/// episode's last real frames; the last imagined frame is decoded (turned into the
/// policy's view: the goal drawn back for a goal-free model) and scored.
///
/// # Errors
/// Non-finite latents, naming the policy and the decision.
pub(super) fn in_world_model(
    ctx: &PlanCtx,
    wm: &WorldModel,
    d: &Decision,
    size: usize,
) -> Result<Imagined, EngineError> {
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
    let z = wm.encode(frames_to_tensor(&frames, size, &device)); // [a (K+1), C, s, s]
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
        let pred =
            roll.step(wm, f, |q, j| d.chunks[q][done + j].as_slice(), &mut rngs).map_err(|source| {
                EngineError::PlanWorldModel { policy: name.to_string(), decision: d.index, source }
            })?; // [b, f, C, s, s]
        last = Some(pred.narrow(1, f - 1, 1).reshape([b, c, ls, ls]));
    }
    let Some(last) = last else { return Ok(Imagined { costs: vec![None; b], frames: vec![Vec::new(); b] }) };
    let mut frames = tensor_to_frames(wm.decode(last));
    let costs = frames
        .iter_mut()
        .enumerate()
        .map(|(q, fr)| {
            let l = &d.live[d.active[q / k]];
            l.imagination.to_observation(fr);
            l.cost.cost(fr)
        })
        .collect();
    Ok(Imagined { costs, frames })
}
