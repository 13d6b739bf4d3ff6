//! A batch of planned episodes in the task's simulator, advanced in lockstep.
//!
//! Every decision (DriftWorld spec §11, GPC-RANK): the policy samples `K`
//! proposals from the real observation (each with its own noise stream, derived
//! from (master seed, policy, episode seed, decision, proposal), so proposal 0 is
//! the same draw under every planner, before the spread); they are spread about their mean; the
//! planner scores each one's last imagined frame with the episode's [`PlanCost`] and the
//! lowest cost is executed for `execute` actions in the simulator. The `none` planner
//! takes proposal 0 without imagining. The world-model planner imagines from the
//! last real frames (the first frame repeated at an episode's start, as `rank`)
//! in one-pass chunks; the simulator planner steps a copy of the true state
//! ([`Env::fork`]) through each proposal and renders its last frame. When the world
//! model plans, the simulator also scores the same proposals, so each decision
//! records whether the two picked the same one and what the world model's pick cost
//! in truth.
//!
//! [`PlanCost`]: harness::task::PlanCost
//! [`Env::fork`]: harness::task::Env::fork

use std::time::Instant;

use harness::policy::{ActionChunk, Observation};
use harness::rng::Rng;
use harness::seed::{derive, fnv1a};
use harness::task::{ModelView, Seen};
use rayon::prelude::*;

use super::imagine::{self, Decision, Imagined};
use super::state::{Live, PlanCtx, PlanOut, PlanRow, Planner};
use crate::EngineError;
use crate::start::{Timing, obs_of, push};

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
/// coordinate `d`, clamped to the action bounds `[low[d], high[d]]`.
pub fn spread(chunks: &mut [ActionChunk], k: usize, s: f32, low: &[f32], high: &[f32]) {
    for group in chunks.chunks_mut(k) {
        let len = group.iter().map(Vec::len).min().unwrap_or(0);
        for t in 0..len {
            let dims = group.iter().map(|c| c[t].len()).min().unwrap_or(0).min(low.len()).min(high.len());
            for d in 0..dims {
                let mean = group.iter().map(|c| c[t][d]).sum::<f32>() / group.len() as f32;
                for c in group.iter_mut() {
                    c[t][d] = (mean + s * (c[t][d] - mean)).clamp(low[d], high[d]);
                }
            }
        }
    }
}

/// Runs the episodes `seeds` under `planner`.
///
/// # Errors
/// A task that cannot be planned in, a policy error, a diverging simulation (real or
/// imagined), or non-finite latents, naming the seed or the policy.
pub fn run_batch(ctx: &PlanCtx, planner: Planner, seeds: &[u64]) -> Result<PlanOut, EngineError> {
    let size = ctx.task.observation_spec().image_size;
    let o = ctx.policy.obs_horizon().max(1);
    let name = ctx.policy.name().to_string();
    let wm = if planner == Planner::WorldModel { ctx.wm } else { None };
    let view =
        if wm.is_some_and(|w| w.cfg.is_goal_free()) { ModelView::GoalFree } else { ModelView::Observation };
    let wm_k = wm.map_or(0, |w| w.cfg.unet.history);
    let mut live = start_episodes(ctx, planner, seeds, (o, wm, view))?;
    let k = if planner == Planner::None { 1 } else { ctx.proposals.max(1) };
    let mut timing = Timing::default();
    let mut steps = 0;
    let mut decision = 0u64;
    let mut active: Vec<usize> = (0..live.len()).filter(|&i| !live[i].row.success).collect();
    while steps < ctx.max_steps && !active.is_empty() {
        // Proposals, k per active episode, episode-major.
        let tp = Instant::now();
        let chunks = propose(ctx, (&live, &active), k, decision, &name)?;
        timing.policy_s += tp.elapsed().as_secs_f64();
        let d = Decision { live: &live, active: &active, chunks: &chunks, k, index: decision };
        let sim_costs = if planner == Planner::None {
            None
        } else {
            let ts = Instant::now();
            let c = imagine::in_simulator(ctx, &d)?;
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
        // Execute the picks in the simulator.
        let ts = Instant::now();
        let e = ctx.execute.min(ctx.max_steps - steps);
        execute_picks(ctx, &mut live, &active, (&chunks, &picks, k), (e, o, wm_k, view))?;
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
    Ok(PlanOut { rows: live.into_iter().map(|l| l.row).collect(), timing, records })
}

/// The policy's proposals at `decision`: `k` per active episode, episode-major, each drawn
/// from its own stream of (master seed, policy, seed, decision, proposal), spread apart
/// when there are several.
///
/// # Errors
/// A policy error, or chunks shorter than the planner imagines or executes.
fn propose(
    ctx: &PlanCtx,
    (live, active): (&[Live], &[usize]),
    k: usize,
    decision: u64,
    name: &str,
) -> Result<Vec<ActionChunk>, EngineError> {
    let (size, spec) = (ctx.task.observation_spec().image_size, ctx.task.action_spec());
    let obs: Vec<Observation> =
        active.iter().flat_map(|&i| std::iter::repeat_n(obs_of(&live[i].seen, size), k)).collect();
    let mut rngs: Vec<Rng> = active
        .iter()
        .flat_map(|&i| {
            let seed = live[i].row.seed;
            (0..k as u64).map(move |j| (seed, j))
        })
        .map(|(seed, j)| Rng::new(derive(ctx.master_seed, &[fnv1a(name), seed, decision, j])))
        .collect();
    let mut chunks = ctx.policy.act(&obs, &mut rngs)?;
    let need = ctx.imagine.max(ctx.execute);
    if chunks.len() != obs.len() || chunks.iter().any(|c| c.len() < need) {
        return Err(EngineError::ShortChunk { policy: name.to_string(), need });
    }
    if k > 1 {
        spread(&mut chunks, k, ctx.spread, &spec.low, &spec.high);
    }
    Ok(chunks)
}

/// Every episode of `seeds` reset for `planner`: its cost (the judge's score or the task's
/// own), its first observations (`o` of them) and world-model history (`wm`'s in `view`),
/// and its row.
///
/// # Errors
/// A seed whose reset fails, or a task without a plan cost and no judge.
fn start_episodes(
    ctx: &PlanCtx,
    planner: Planner,
    seeds: &[u64],
    (o, wm, view): (usize, Option<&world_model::model::WorldModel>, ModelView),
) -> Result<Vec<Live>, EngineError> {
    let kind = ctx.task.score_kind();
    let wm_k = wm.map_or(0, |w| w.cfg.unet.history);
    let thr = kind.threshold();
    let mut live = Vec::with_capacity(seeds.len());
    for &seed in seeds {
        let env = ctx.task.reset(seed)?;
        let cannot = || EngineError::CannotPlan { task: ctx.task.name().to_string() };
        let cost: Box<dyn harness::task::PlanCost> = match &ctx.judge {
            // The judge's score of a frame, a pose judge's through the episode's own judge.
            Some(j) => Box::new(harness::judge::JudgedCost(Box::new(harness::judge::Replaced {
                scorer: j.clone(),
                checks: env.judge(),
            }))),
            None => env.plan_cost().ok_or_else(cannot)?,
        };
        let first = env.observe();
        let wm_first = if wm.is_some() { env.model_frame(view) } else { first.frame.clone() };
        let raw = env.score();
        live.push(Live {
            seen: (0..o).map(|_| first.clone()).collect(),
            wm_hist: (0..wm_k).map(|_| wm_first.clone()).collect(),
            wm_first,
            imagination: env.imagination(view),
            cost,
            row: PlanRow {
                planner: planner.name().to_string(),
                seed,
                score: kind.reward(raw),
                max_coverage: raw,
                final_coverage: raw,
                success: raw > thr,
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
    Ok(live)
}

/// Executes each active episode's picked proposal (its first `e` actions) in the
/// simulator, on the worker threads.
///
/// # Errors
/// The first episode whose simulation fails.
fn execute_picks(
    ctx: &PlanCtx,
    live: &mut [Live],
    active: &[usize],
    (chunks, picks, k): (&[ActionChunk], &[usize], usize),
    (e, o, wm_k, view): (usize, usize, usize, ModelView),
) -> Result<(), EngineError> {
    let kind = ctx.task.score_kind();
    let mut pos_of = vec![None; live.len()];
    for (p, &i) in active.iter().enumerate() {
        pos_of[i] = Some(p);
    }
    let results: Vec<Result<(), EngineError>> = ctx.pool.install(|| {
        live.par_iter_mut()
            .zip(pos_of.par_iter())
            .map(|(l, p)| match p {
                Some(p) => execute(l, &chunks[p * k + picks[*p]][..e], o, (wm_k, view), kind),
                None => Ok(()),
            })
            .collect()
    });
    results.into_iter().collect::<Result<Vec<()>, _>>()?;
    Ok(())
}

/// Executes `actions` in the real environment, updating the score and the histories
/// (the policy's, and the world model's `keep_wm` frames in its `view`).
fn execute(
    l: &mut Live,
    actions: &[Vec<f32>],
    o: usize,
    (keep_wm, view): (usize, ModelView),
    kind: harness::task::ScoreKind,
) -> Result<(), EngineError> {
    let n = actions.len();
    // Only the frames the histories keep are rendered.
    let keep = o.max(keep_wm);
    let thr = kind.threshold();
    for (j, a) in actions.iter().enumerate() {
        let raw = l.env.step(a)?;
        let r = &mut l.row;
        r.score = r.score.max(kind.reward(raw));
        r.max_coverage = r.max_coverage.max(raw);
        r.final_coverage = raw;
        r.success |= raw > thr;
        r.steps += 1;
        if j + keep >= n {
            let seen: Seen = l.env.observe();
            if keep_wm > 0 {
                let wm_frame =
                    if view == ModelView::GoalFree { l.env.model_frame(view) } else { seen.frame.clone() };
                push(&mut l.wm_hist, wm_frame, keep_wm);
            }
            push(&mut l.seen, seen, o);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use harness::policy::{Policy, PolicyError};

    use super::*;

    /// Proposes 8 targets near the centre, each from its own noise stream.
    struct Wander;

    impl Policy for Wander {
        fn name(&self) -> &str {
            "wander"
        }
        fn obs_horizon(&self) -> usize {
            2
        }
        fn action_horizon(&self) -> usize {
            8
        }
        fn act(&self, obs: &[Observation], rngs: &mut [Rng]) -> Result<Vec<ActionChunk>, PolicyError> {
            Ok(obs
                .iter()
                .zip(rngs)
                .map(|(_, r)| (0..8).map(|_| vec![256.0 + 60.0 * r.normal() as f32, 256.0]).collect())
                .collect())
        }
    }

    fn plan(planner: Planner, threads: usize) -> PlanOut {
        let task = scenarios::load_task("pusht").unwrap();
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let ctx = PlanCtx {
            task: task.as_ref(),
            policy: &Wander,
            wm: None,
            proposals: 3,
            imagine: 8,
            execute: 4,
            spread: 1.0,
            margin: 0.0,
            master_seed: 5,
            max_steps: 10,
            pool: &pool,
            record: &[11],
            judge: None,
        };
        run_batch(&ctx, planner, &[11, 12]).unwrap()
    }

    #[test]
    fn the_simulator_planner_runs_every_decision_alike_on_any_thread_count() {
        let one = plan(Planner::Simulator, 1);
        // 10 steps at 4 per decision: decisions of 4, 4 and 2 actions.
        for r in &one.rows {
            assert_eq!((r.steps, r.decisions, r.planner.as_str()), (10, 3, "simulator"), "{r:?}");
            assert!(r.agreed.is_none() && r.regret.is_none(), "only the world model's picks are checked");
        }
        // Three proposals differ, so some decision executes another than the first.
        assert!(one.rows.iter().any(|r| r.replaced > 0), "{:?}", one.rows);
        // Seed 11 is recorded: per decision, the real frame and the simulator's outcome.
        assert_eq!(one.records.len(), 1);
        let (seed, rec) = &one.records[0];
        assert_eq!((*seed, rec.len()), (11, 3));
        assert!(rec.iter().all(|[real, wm, sim]| !real.is_empty() && wm.is_empty() && !sim.is_empty()));
        let two = plan(Planner::Simulator, 2);
        assert_eq!(one.rows, two.rows, "two threads give the rows one does");
        assert_eq!(one.records, two.records);
        // The policy alone executes proposal 0 and never imagines.
        let none = plan(Planner::None, 1);
        assert!(none.rows.iter().all(|r| r.replaced == 0 && r.decisions == 3), "{:?}", none.rows);
    }

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
        spread(&mut c, 2, 2.0, &[0.0, 0.0], &[512.0, 512.0]);
        assert_eq!(c, vec![one(5.0, 1.0), one(25.0, 1.0), one(495.0, 7.0), one(512.0, 7.0)]);
    }
}
