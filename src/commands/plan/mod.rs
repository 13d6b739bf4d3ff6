//! `evalharness plan`: GPC-RANK (DriftWorld spec §11), run by [`engine::plan`] on
//! any task with a planning cost (Push-T). A diffusion policy proposes several
//! action chunks per decision; a planner imagines each and executes the best in
//! the simulator. Three planners run on the same seeds: `none` (the
//! policy alone), `world-model` (GPC-RANK) and `simulator` (the same ranking with
//! perfect imagination), so the run measures what planning in the world model
//! gains over the policy and how much of the simulator's gain it keeps.
//!
//! Output folder: `config.json` (resolved arguments), `episodes.jsonl` (appended as
//! batches finish; `--resume` skips the batches it holds), `episodes.csv` (sorted), `results.json` (per planner: mean
//! score and success rate with 95% CIs, the paired difference from `none`; for the
//! world model, how often its pick matched the simulator's and what its picks
//! cost in truth); `filmstrips/<planner>_seed<S>.png` for the first `--record`
//! seeds (per decision: the real frame; the world model's and the simulator's last
//! frame of the proposal picked).

mod results;

use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use engine::plan::results::{PlanSettings, PlanTiming, summarise};
use harness::policy::Policy;
use policies::diffusion::DiffusionPolicy;
use policies::dir::{checkpoint_name, diffusion_config, diffusion_weights, read_policy_file};

use crate::cli::PlanArgs;
use crate::output::write_json;
use crate::progress;
use engine::Timing;
use engine::plan::{PlanCtx, PlanRow, Planner, plan_key, run_batch};

/// Loads the proposing policy, returning chunks of max(imagine, execute) actions (it
/// still predicts its whole horizon; only the slice it returns is longer), with the
/// resolved `--imagine` and `--execute`. Evalharness's own diffusion policies and imported
/// ones (`gpc-diffusion`, `lerobot-diffusion`: GPC-RANK's own proposers) propose.
fn load_proposer(
    a: &PlanArgs,
    task: &dyn harness::task::Task,
    device: &burn::tensor::Device,
) -> Result<(Box<dyn Policy>, usize, usize)> {
    let image_size = task.observation_spec().image_size;
    let dir = &a.policy;
    // The kind first: other kinds' policy.json has other fields.
    let Some(kind) = policies::dir::policy_kind(dir) else {
        // Unreadable, not JSON, or without a kind: the reader names what is wrong.
        read_policy_file(dir)?;
        bail!("{}: policy.json names no kind", dir.display());
    };
    let file = match kind.as_str() {
        "diffusion" | "gpc-diffusion" | "lerobot-diffusion" | "robomimic-diffusion" => read_policy_file(dir)?,
        _ => bail!(
            "{}: plan needs a diffusion policy (its sampling noise makes the proposals), this one is kind \"{kind}\"",
            dir.display()
        ),
    };
    // (frame side, most actions ahead, own action horizon, horizon, observations)
    let (size, max, own, horizon, obs) = if kind == "diffusion" {
        let c = diffusion_config(dir, &file)?;
        (c.net.image_size, c.max_action_horizon(), c.action_horizon, c.horizon, c.net.obs_horizon)
    } else {
        let c: policies::imported_policy::ImportedConfig = serde_json::from_value(file.config.clone())
            .with_context(|| format!("policy {}: policy.json \"config\"", dir.display()))?;
        (c.net.image_size, c.max_action_horizon(), c.action_horizon, c.horizon, c.net.obs_horizon)
    };
    if size != image_size {
        bail!(
            "{}: takes {size}x{size} frames, the scenario renders {image_size}x{image_size}",
            dir.display()
        );
    }
    let imagine = a.imagine.unwrap_or(max);
    let execute = a.execute.unwrap_or(own);
    for (flag, v) in [("--imagine", imagine), ("--execute", execute)] {
        if v == 0 || v > max {
            bail!(
                "{flag} {v}: policy {} predicts {max} actions from the current step (horizon {horizon}, {obs} observations)",
                dir.display(),
            );
        }
    }
    let returns = imagine.max(execute);
    if kind != "diffusion" {
        let expect = policies::kinds::expectations(task);
        let p = policies::imported_policy::load_returning(dir, file, &expect, device, Some(returns))?;
        return Ok((p, imagine, execute));
    }
    let mut cfg = diffusion_config(dir, &file)?;
    let net = diffusion_weights(dir, &cfg, device)?;
    cfg.action_horizon = returns;
    let name = checkpoint_name(dir);
    let spec = task.action_spec();
    let bounds = (spec.low, spec.high);
    Ok((Box::new(DiffusionPolicy::new(name, cfg, file.normalisation, bounds, net, device)), imagine, execute))
}

/// The planners `--planners` names, sorted and once each, after the flags that every run
/// needs are checked.
///
/// # Errors
/// A zero step limit, batch or proposal count, a spread or margin out of range, or no planner.
fn planners_of(a: &PlanArgs) -> Result<Vec<Planner>> {
    if a.max_steps == 0 || a.batch == 0 || a.proposals == 0 {
        bail!("--max-steps, --batch and --proposals must be positive");
    }
    if !(a.spread.is_finite() && a.spread > 0.0) {
        bail!("--spread {}: must be a positive number", a.spread);
    }
    if !(a.margin.is_finite() && a.margin >= 0.0) {
        bail!("--margin {}: must be a number >= 0", a.margin);
    }
    let mut planners: Vec<Planner> = a.planners.iter().map(|&p| p.into()).collect();
    planners.sort();
    planners.dedup();
    if planners.is_empty() {
        bail!("--planners: name at least one of none, world-model, simulator");
    }
    Ok(planners)
}

/// The run's `config.json`: its settings, the inputs' fingerprints, and the cost the
/// planners minimise.
fn plan_config(
    a: &PlanArgs,
    planners: &[Planner],
    wm: Option<&world_model::model::WorldModel>,
    (imagine, execute): (usize, usize),
    fingerprints: std::collections::BTreeMap<String, String>,
) -> runner::PlanConfig {
    runner::PlanConfig {
        command: crate::stdout::command_line().join(" "),
        scenario: a.scenario.clone(),
        policy: a.policy.clone(),
        world_model: wm.as_ref().map(|_| a.world_model.clone()),
        world_model_config: wm.as_ref().map(|w| w.cfg.clone()),
        planners: planners.iter().map(|p| p.name().to_string()).collect(),
        proposals: a.proposals,
        imagine,
        execute,
        spread: a.spread,
        margin: a.margin,
        judge: a.judge.clone(),
        cost: match &a.judge {
            Some(_) => "1 - the judge's score of the last imagined frame",
            None => "mean distance (world units) of the last imagined frame's block pixels from the goal T",
        }
        .to_string(),
        episodes: a.episodes,
        seed_start: a.seed_start,
        max_steps: a.max_steps,
        batch: a.batch,
        seed: a.seed,
        bootstrap: a.bootstrap,
        record: a.record,
        fingerprints,
    }
}

/// The world model, when a planner imagines in it, checked to draw the task's frame size.
///
/// # Errors
/// A world model that does not load, or of another frame size.
fn world_model_of(
    a: &PlanArgs,
    planners: &[Planner],
    size: usize,
    device: &burn::tensor::Device,
) -> Result<Option<world_model::model::WorldModel>> {
    Ok(if planners.contains(&Planner::WorldModel) {
        let wm = runner::inputs::load_world_model(&a.world_model, a.alpha, None, device)?;
        if wm.image_size() != size {
            bail!(
                "world model {} generates {1}x{1} frames, the scenario renders {size}x{size}",
                a.world_model.display(),
                wm.image_size(),
            );
        }
        Some(wm)
    } else {
        None
    })
}

/// Runs every planner on every batch of seeds not in `rows` yet (a resumed run's), each
/// batch appended whole to `jsonl` with its filmstrips in `filmstrips`; returns the time
/// spent.
///
/// # Errors
/// A batch that fails, naming its planner and seeds, or rows or filmstrips not written.
fn run_planners(
    ctx: &PlanCtx<'_>,
    (planners, batches): (&[Planner], &[&[u64]]),
    rows: &mut Vec<PlanRow>,
    (jsonl, filmstrips, size): (&std::path::Path, &std::path::Path, usize),
    pb: &indicatif::ProgressBar,
) -> Result<Timing> {
    let mut timing = Timing::default();
    for &planner in planners {
        for &batch in batches {
            let done = |s: &u64| rows.iter().any(|r| r.planner == planner.name() && r.seed == *s);
            if batch.iter().all(done) {
                pb.inc(batch.len() as u64);
                continue;
            }
            // Batches are appended whole, and `resume_rows` dropped any part of one.
            let out = run_batch(ctx, planner, batch)
                .with_context(|| format!("planner {} on seeds {:?}", planner.name(), batch))?;
            harness::rows::append_rows(jsonl, &out.rows)?;
            timing.add(&out.timing);
            for (seed, rec) in &out.records {
                let png = filmstrips.join(format!("{}_seed{seed}.png", planner.name()));
                results::write_strip(&png, rec, size)?;
            }
            rows.extend(out.rows);
            pb.inc(batch.len() as u64);
        }
        tracing::info!(planner = planner.name(), "done");
    }
    Ok(timing)
}

/// `evalharness plan`.
pub fn run(a: &PlanArgs, quiet: bool) -> Result<ExitCode> {
    let planners = planners_of(a)?;
    let seeds: Vec<u64> = harness::seed::range(a.seed_start, a.episodes as u64)?.collect();
    let task = crate::scenario::load_task(&a.scenario)?;
    let size = task.observation_spec().image_size;
    // Refused before anything is loaded or written: the task must be one to plan in.
    let probe = task.reset(seeds[0]).with_context(|| format!("resetting seed {}", seeds[0]))?;
    if (a.judge.is_none() && probe.plan_cost().is_none()) || probe.fork().is_none() {
        return Err(engine::EngineError::CannotPlan { task: task.name().to_string() }.into());
    }
    let device = nn::device::selected()?;
    let wm = world_model_of(a, &planners, size, &device)?;
    let (policy, imagine, execute) = load_proposer(a, task.as_ref(), &device)?;
    let judge = match &a.judge {
        Some(dir) => {
            let j = runner::inputs::load_judge(dir, task.as_ref(), &device)?;
            Some(std::sync::Arc::new(j) as std::sync::Arc<dyn harness::judge::Judge>)
        }
        None => None,
    };
    // Every input is checked; only now is the output folder touched.
    let fingerprints = runner::inputs::fingerprints(
        wm.as_ref().map(|w| (a.world_model.as_path(), w)),
        std::slice::from_ref(&a.policy),
        a.judge.as_deref(),
        &a.scenario,
        task.parameters().as_ref(),
    )?;
    let mut listed = crate::output::Inputs::new().scenario(&a.scenario).add("--policy", &a.policy);
    if let Some(dir) = &a.judge {
        listed = listed.add("--judge", dir);
    }
    if wm.is_some() {
        listed = listed.world_model("--world-model", &a.world_model);
    }
    let (out_dir, jsonl) = ranking::prepare_run(&a.out, &listed, a.resume, a.force)?;
    let config = plan_config(a, &planners, wm.as_ref(), (imagine, execute), fingerprints);
    let config_file = a.out.join("config.json");
    if a.resume {
        runner::resume::check(&config_file, &config)?;
    }
    runner::config::write(&config_file, &config)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.jobs.max(1))
        .build()
        .context("starting worker threads")?;
    let ctx = PlanCtx {
        task: task.as_ref(),
        policy: policy.as_ref(),
        wm: wm.as_ref(),
        proposals: a.proposals,
        imagine,
        execute,
        spread: a.spread,
        margin: a.margin,
        master_seed: a.seed,
        max_steps: a.max_steps,
        pool: &pool,
        record: &seeds[..a.record.min(seeds.len())],
        judge,
    };
    let filmstrips = a.out.join("filmstrips");
    if a.record > 0 {
        std::fs::create_dir_all(&filmstrips).with_context(|| format!("creating {}", filmstrips.display()))?;
    }
    let pb = progress::bar((planners.len() * a.episodes) as u64, "plan", quiet);
    let started = Instant::now();
    let batches: Vec<&[u64]> = seeds.chunks(a.batch).collect();
    let mut rows: Vec<PlanRow> =
        harness::rows::resume_rows(&jsonl, |r| harness::rows::whole_batches(r, &batches, plan_key, &[()]))?;
    let timing = run_planners(&ctx, (&planners, &batches), &mut rows, (&jsonl, &filmstrips, size), &pb)?;
    pb.finish_and_clear();
    let settings = PlanSettings {
        policy: policy.name().to_string(),
        proposals: a.proposals,
        imagine,
        execute,
        episodes: a.episodes,
        seed_start: a.seed_start,
    };
    let timing = PlanTiming::new(started.elapsed().as_secs_f64(), &timing);
    let res = summarise(&rows, &planners, a.bootstrap, a.seed, settings, timing);
    write_json(&a.out.join("results.json"), &res)?;
    results::write_csv(&a.out.join("episodes.csv"), &rows)?;
    out_dir.finish(true)?;
    results::print_summary(&res, &a.out);
    Ok(ExitCode::SUCCESS)
}
