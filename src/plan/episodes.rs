//! A batch of planned episodes in MuJoCo, advanced in lockstep.
//!
//! Every decision (DriftWorld spec §11, GPC-RANK): the policy samples `K`
//! proposals from the real observation (each with its own noise stream, derived
//! from (master seed, policy, episode seed, decision, proposal), so proposal 0 is
//! the same draw under every planner, before the spread); they are spread about their mean; the
//! planner scores each one's last imagined frame with [`GoalDistance`] and the
//! lowest cost is executed for `execute` actions in MuJoCo. The `none` planner
//! takes proposal 0 without imagining. The world-model planner imagines from the
//! last real frames (the first frame repeated at an episode's start, as `rank`)
//! in one-pass chunks; the simulator planner steps a copy of the true state
//! through each proposal and renders its last frame. When the world model plans,
//! the simulator also scores the same proposals, so each decision records whether
//! the two picked the same one and what the world model's pick cost in truth.

use std::time::Instant;

use anyhow::{Result, anyhow, bail};
use harness::policy::{ActionChunk, Observation};
use harness::rng::Rng;
use harness::seed::{derive, fnv1a};
use rayon::prelude::*;
use scenarios::pusht::PushTEnv;
use scenarios::pusht::frame_score::FrameScorer;
use scenarios::pusht::plan_cost::GoalDistance;
use scenarios::pusht::render::Rasterizer;

use super::imagine::{self, Decision, Imagined};
use super::state::{BatchOut, Ctx, Live, PlanRow};
use crate::cli::Planner;
use engine::{Timing, obs_of, push};
use harness::task::Seen;

/// Index of the lowest cost (the first on ties; proposals without a cost are never
/// picked unless none has one, and then the first is).
pub fn pick(costs: &[Option<f64>]) -> usize {
    let mut best: Option<(usize, f64)> = None;
    for (j, c) in costs.iter().enumerate() {
        if let Some(c) = *c
            && best.is_none_or(|(_, b)| c < b)
        {
            best = Some((j, c));
        }
    }
    best.map_or(0, |(j, _)| j)
}

/// [`pick`], keeping proposal 0 unless the pick's cost is at least `margin` below its.
pub fn pick_with_margin(costs: &[Option<f64>], margin: f64) -> usize {
    let j = pick(costs);
    match (costs.first().copied().flatten(), costs.get(j).copied().flatten()) {
        (Some(c0), Some(cj)) if cj > c0 - margin => 0,
        _ => j,
    }
}

/// `a ← mean + s·(a − mean)` over each episode's `k` consecutive proposals, per step and
/// coordinate, clamped to the world `[0, hi]`.
pub fn spread(chunks: &mut [ActionChunk], k: usize, s: f32, hi: f32) {
    for group in chunks.chunks_mut(k) {
        let len = group.iter().map(Vec::len).min().unwrap_or(0);
        for t in 0..len {
            for d in 0..2 {
                let mean = group.iter().map(|c| c[t][d]).sum::<f32>() / group.len() as f32;
                for c in group.iter_mut() {
                    c[t][d] = (mean + s * (c[t][d] - mean)).clamp(0.0, hi);
                }
            }
        }
    }
}

/// Runs the episodes `seeds` under `planner`.
///
/// # Errors
/// A policy error, a diverging simulation (real or imagined), or non-finite latents,
/// naming the seed or the policy.
pub fn run_batch(ctx: &Ctx, planner: Planner, seeds: &[u64]) -> Result<BatchOut> {
    let raster = Rasterizer::new(ctx.cfg);
    let size = raster.size();
    let o = ctx.policy.obs_horizon().max(1);
    let name = ctx.policy.name().to_string();
    let wm = if planner == Planner::WorldModel { ctx.wm } else { None };
    let goal_free = wm.is_some_and(|w| w.cfg.is_goal_free());
    let wm_k = wm.map_or(0, |w| w.cfg.unet.history);
    let thr = ctx.cfg.task.success_coverage;
    let mut live = Vec::with_capacity(seeds.len());
    for &seed in seeds {
        let mut env = PushTEnv::new(ctx.model.clone(), ctx.cfg);
        env.reset(seed)?;
        let (st, goal) = (env.state(), env.goal());
        let first = raster.render(&st, &goal);
        let wm_first = if goal_free { raster.render_without_goal(&st) } else { first.clone() };
        let pos = st.agent.map(|v| v as f32);
        let cov = env.score().coverage;
        live.push(Live {
            seen: (0..o).map(|_| Seen { frame: first.clone(), proprio: pos.to_vec() }).collect(),
            wm_hist: (0..wm_k).map(|_| wm_first.clone()).collect(),
            wm_first,
            scorer: FrameScorer::new(ctx.cfg, &goal, size),
            cost: GoalDistance::new(ctx.cfg, &goal, size),
            row: PlanRow {
                planner: planner.name().to_string(),
                seed,
                score: (cov / thr).clamp(0.0, 1.0),
                max_coverage: cov,
                final_coverage: cov,
                success: cov > thr,
                steps: 0,
                decisions: 0,
                replaced: 0,
                agreed: wm.map(|_| 0),
                regret: wm.map(|_| 0.0),
                regret_random: wm.map(|_| 0.0),
            },
            record: ctx.record.contains(&seed).then(Vec::new),
            env,
        });
    }
    let k = if planner == Planner::None { 1 } else { ctx.proposals.max(1) };
    let mut timing = Timing::default();
    let mut steps = 0;
    let mut decision = 0u64;
    let mut active: Vec<usize> = (0..live.len()).filter(|&i| !live[i].row.success).collect();
    while steps < ctx.max_steps && !active.is_empty() {
        // Proposals, k per active episode, episode-major.
        let tp = Instant::now();
        let obs: Vec<Observation> =
            active.iter().flat_map(|&i| std::iter::repeat_n(obs_of(&live[i].seen, size), k)).collect();
        let mut rngs: Vec<Rng> = active
            .iter()
            .flat_map(|&i| {
                let seed = live[i].row.seed;
                (0..k as u64).map(move |j| (seed, j))
            })
            .map(|(seed, j)| Rng::new(derive(ctx.master_seed, &[fnv1a(&name), seed, decision, j])))
            .collect();
        let mut chunks = ctx.policy.act(&obs, &mut rngs).map_err(|e| anyhow!(e))?;
        let need = ctx.imagine.max(ctx.execute);
        if chunks.len() != obs.len() || chunks.iter().any(|c| c.len() < need) {
            bail!("policy {name} returned fewer than {need} actions per proposal");
        }
        if k > 1 {
            spread(&mut chunks, k, ctx.spread, ctx.cfg.world.size as f32);
        }
        timing.policy_s += tp.elapsed().as_secs_f64();
        let d = Decision { live: &live, active: &active, chunks: &chunks, k, index: decision };
        let sim_costs = if planner == Planner::None {
            None
        } else {
            let ts = Instant::now();
            let c = imagine::in_simulator(ctx, &d, &raster)?;
            timing.sim_s += ts.elapsed().as_secs_f64();
            Some(c)
        };
        let sim = sim_costs.as_ref().map_or(&[][..], |o| o.costs.as_slice());
        let mut wm_out = None;
        let picks: Vec<usize> = match (planner, wm) {
            (Planner::WorldModel, Some(w)) => {
                let tw = Instant::now();
                let out = imagine::in_world_model(ctx, w, &d, size)?;
                timing.world_model_s += tw.elapsed().as_secs_f64();
                timing.frames += (out.costs.len() * ctx.imagine) as u64;
                let costs = &wm_out.insert(out).costs;
                active
                    .iter()
                    .enumerate()
                    .map(|(p, &i)| {
                        let (ours, truth) = (&costs[p * k..(p + 1) * k], &sim[p * k..(p + 1) * k]);
                        let (j, best) = (pick_with_margin(ours, ctx.margin), pick(truth));
                        let row = &mut live[i].row;
                        *row.agreed.get_or_insert(0) += usize::from(j == best);
                        if let (Some(cj), Some(cb)) = (truth[j], truth[best]) {
                            *row.regret.get_or_insert(0.0) += cj - cb;
                            let scored: Vec<f64> = truth.iter().flatten().map(|c| c - cb).collect();
                            *row.regret_random.get_or_insert(0.0) +=
                                scored.iter().sum::<f64>() / scored.len() as f64;
                        }
                        j
                    })
                    .collect()
            }
            (Planner::Simulator, _) => {
                (0..active.len()).map(|p| pick_with_margin(&sim[p * k..(p + 1) * k], ctx.margin)).collect()
            }
            _ => vec![0; active.len()],
        };
        // Recorded episodes keep, per decision, the real frame and what each imagination
        // showed of the picked proposal's outcome.
        for (p, &i) in active.iter().enumerate() {
            let q = p * k + picks[p];
            let (real, l) = (live[i].seen.back().map(|f| f.frame.clone()), &mut live[i]);
            if let (Some(rec), Some(real)) = (l.record.as_mut(), real) {
                let get = |o: Option<&Imagined>| o.and_then(|o| o.frames.get(q)).cloned().unwrap_or_default();
                rec.push([real, get(wm_out.as_ref()), get(sim_costs.as_ref())]);
            }
        }
        // Execute the picks in MuJoCo.
        let ts = Instant::now();
        let e = ctx.execute.min(ctx.max_steps - steps);
        let mut pos_of = vec![None; live.len()];
        for (p, &i) in active.iter().enumerate() {
            pos_of[i] = Some(p);
        }
        let results: Vec<Result<()>> = ctx.pool.install(|| {
            live.par_iter_mut()
                .zip(pos_of.par_iter())
                .map(|(l, p)| match p {
                    Some(p) => execute(l, &chunks[p * k + picks[*p]][..e], &raster, o, wm_k, goal_free, thr),
                    None => Ok(()),
                })
                .collect()
        });
        results.into_iter().collect::<Result<Vec<()>>>()?;
        for (p, &i) in active.iter().enumerate() {
            let row = &mut live[i].row;
            row.decisions += 1;
            row.replaced += usize::from(picks[p] != 0);
        }
        timing.sim_s += ts.elapsed().as_secs_f64();
        steps += e;
        decision += 1;
        active.retain(|&i| !live[i].row.success);
    }
    let records = live.iter_mut().filter_map(|l| Some((l.row.seed, l.record.take()?))).collect();
    Ok(BatchOut { rows: live.into_iter().map(|l| l.row).collect(), timing, records })
}

/// Executes `actions` in the real environment, updating the score and the histories.
fn execute(
    l: &mut Live,
    actions: &[Vec<f32>],
    raster: &Rasterizer,
    o: usize,
    keep_wm: usize,
    goal_free: bool,
    thr: f64,
) -> Result<()> {
    let n = actions.len();
    // Only the frames the histories keep are rendered.
    let keep = o.max(keep_wm);
    for (j, a) in actions.iter().enumerate() {
        let sc = l.env.step([f64::from(a[0]), f64::from(a[1])])?;
        let r = &mut l.row;
        r.score = r.score.max((sc.coverage / thr).clamp(0.0, 1.0));
        r.max_coverage = r.max_coverage.max(sc.coverage);
        r.final_coverage = sc.coverage;
        r.success |= sc.coverage > thr;
        r.steps += 1;
        if j + keep >= n {
            let (st, goal) = (l.env.state(), l.env.goal());
            let frame = raster.render(&st, &goal);
            if keep_wm > 0 {
                let wm_frame = if goal_free { raster.render_without_goal(&st) } else { frame.clone() };
                push(&mut l.wm_hist, wm_frame, keep_wm);
            }
            push(&mut l.seen, Seen { frame, proprio: st.agent.map(|v| v as f32).to_vec() }, o);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pick_takes_the_first_lowest_cost_and_skips_missing_ones() {
        assert_eq!(pick(&[Some(3.0), Some(1.0), Some(1.0)]), 1);
        assert_eq!(pick(&[None, Some(5.0), Some(2.0)]), 2);
        // No proposal shows a block: the first (the policy's own) is executed.
        assert_eq!(pick(&[None, None]), 0);
        assert_eq!(pick(&[]), 0);
    }

    #[test]
    fn a_margin_keeps_the_first_proposal_unless_another_is_clearly_better() {
        let c = [Some(10.0), Some(8.0), Some(12.0)];
        // The best is 2 units better: taken at margin 2, not at 2.5.
        assert_eq!(pick_with_margin(&c, 0.0), 1);
        assert_eq!(pick_with_margin(&c, 2.0), 1);
        assert_eq!(pick_with_margin(&c, 2.5), 0);
        // A first proposal without a cost never blocks a scored one.
        assert_eq!(pick_with_margin(&[None, Some(8.0)], 100.0), 1);
    }

    #[test]
    fn spread_scales_about_each_episodes_mean() {
        // Episode 0's two proposals at x = 10 and 20 (mean 15) move to 15 ∓ 2·5 = 5, 25;
        // episode 1's at 500 and 510 (mean 505) to 495 and 515, clamped to 512.
        let one = |x: f32, y: f32| vec![vec![x, y]];
        let mut c = vec![one(10.0, 1.0), one(20.0, 1.0), one(500.0, 7.0), one(510.0, 7.0)];
        spread(&mut c, 2, 2.0, 512.0);
        assert_eq!(c, vec![one(5.0, 1.0), one(25.0, 1.0), one(495.0, 7.0), one(512.0, 7.0)]);
    }
}
