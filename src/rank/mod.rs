//! `evalharness rank`: every policy checkpoint, many seeded episodes, two branches
//! (MuJoCo and the world model) from the same initial state; per-policy scores
//! with CIs and how well the world model's ranking agrees with MuJoCo's.
//!
//! Output folder: `config.json` (resolved arguments), `episodes.jsonl` (appended
//! as batches finish), `episodes.csv` and `episodes.parquet` (the same rows, sorted),
//! `results.json`. `--resume` skips episodes
//! already in `episodes.jsonl`; `--shard i/n` runs every n-th batch.

mod media;
pub mod merge;
pub mod paired;
pub mod report;
pub mod results;
pub(crate) mod resume;
pub mod scene;
mod schedule;
pub mod start;

use std::path::Path;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use policies::dir::{Expectations, checkpoint_dirs, checkpoint_name};
use reports::episodes::{EpisodeRecord, write_episodes_parquet};

use crate::policy_kinds::load_any;
use scenarios::pusht::PushTPhysics;
use serde_json::{Value, json};
use world_model::model::WorldModel;

use crate::cli::RankArgs;
use crate::output::write_json;
use crate::progress;
use paired::Setup;
use results::{EpisodeRow, append_rows, read_rows, summarise};
use schedule::Batch;

/// Parses `--shard i/n`.
fn parse_shard(s: Option<&str>) -> Result<(usize, usize)> {
    let Some(s) = s else { return Ok((0, 1)) };
    let (i, n) = s.split_once('/').with_context(|| format!("--shard {s}: expected i/n"))?;
    let (i, n): (usize, usize) = (i.parse().context("--shard index")?, n.parse().context("--shard count")?);
    if n == 0 || i >= n {
        bail!("--shard {s}: need 0 <= i < n");
    }
    Ok((i, n))
}

/// `evalharness rank`.
pub fn run(a: &RankArgs, quiet: bool) -> Result<ExitCode> {
    let (shard, shards) = parse_shard(a.shard.as_deref())?;
    if a.episodes == 0 || a.max_steps == 0 || a.batch == 0 {
        bail!("--episodes, --max-steps and --batch must be positive");
    }
    let jsonl = a.out.join("episodes.jsonl");
    crate::output::run_dir(&a.out, a.resume, a.force)?;
    let cfg = crate::scenario::load_pusht(&a.scenario)?;
    let model = PushTPhysics::compile(&cfg)?;
    let device = world_model::device::selected()?;
    let wm = load_world_model(&a.world_model, a.alpha, &device)?;
    let dirs = checkpoint_dirs(&a.policies)?;
    let config = json!({
        "command": std::env::args().collect::<Vec<_>>().join(" "),
        "scenario": a.scenario, "policies": a.policies, "world_model": a.world_model,
        "world_model_config": serde_json::to_value(&wm.cfg)?,
        "episodes": a.episodes, "seed_start": a.seed_start, "max_steps": a.max_steps,
        "batch": a.batch, "seed": a.seed, "bootstrap": a.bootstrap, "shard": [shard, shards],
        "checkpoints": dirs.iter().map(|d| d.display().to_string()).collect::<Vec<_>>(),
    });
    if a.resume {
        resume::check_config(&a.out.join("config.json"), &config)?;
    }
    write_json(&a.out.join("config.json"), &config)?;
    let mut rows: Vec<EpisodeRow> = read_rows(&jsonl)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.jobs.max(1))
        .build()
        .context("starting worker threads")?;
    let setup = Setup { cfg: &cfg, model: &model, master_seed: a.seed, max_steps: a.max_steps };
    let expect = Expectations { image_size: cfg.render.size as usize, action_dim: 2 };
    let seeds: Vec<u64> = (0..a.episodes as u64).map(|i| a.seed_start + i).collect();
    let batches: Vec<&[u64]> = seeds.chunks(a.batch).collect();
    let pb = progress::bar((dirs.len() * a.episodes) as u64, "rank", quiet);
    let mut failed: Vec<Value> = Vec::new();
    let mut names = Vec::new();
    let started = Instant::now();
    // Load every policy first (a policy that fails to load is reported and left out),
    // then run all their batches on the workers.
    let mut loaded: Vec<(usize, Box<dyn harness::policy::Policy>)> = Vec::new();
    for (pi, dir) in dirs.iter().enumerate() {
        let name = checkpoint_name(dir);
        names.push(name.clone());
        match load_any(dir, expect, &device, &cfg, &model) {
            Ok(p) => loaded.push((pi, p)),
            Err(e) => {
                tracing::error!("{e}; continuing with the other policies");
                failed.push(json!({"policy": name, "error": e.to_string()}));
                pb.inc(a.episodes as u64);
            }
        }
    }
    let mut jobs: Vec<Batch> = Vec::new();
    for (li, (pi, _)) in loaded.iter().enumerate() {
        for (bi, batch) in batches.iter().enumerate() {
            let name = &names[*pi];
            if (pi * batches.len() + bi) % shards != shard {
                pb.inc(batch.len() as u64);
                continue;
            }
            let todo: Vec<u64> = batch
                .iter()
                .copied()
                .filter(|s| rows.iter().filter(|r| &r.policy == name && r.seed == *s).count() < 2)
                .collect();
            pb.inc((batch.len() - todo.len()) as u64);
            if !todo.is_empty() {
                jobs.push(Batch { policy: li, seeds: todo });
            }
        }
    }
    let policies: Vec<&dyn harness::policy::Policy> = loaded.iter().map(|(_, p)| p.as_ref()).collect();
    let mut done = |j: usize, out: schedule::BatchResult| -> Result<()> {
        let (name, todo) = (&names[loaded[jobs[j].policy].0], &jobs[j].seeds);
        match out {
            Ok(new) => {
                // Drop half-written pairs of these seeds (from a killed run) before appending.
                rows.retain(|r| !(&r.policy == name && todo.contains(&r.seed)));
                append_rows(&jsonl, &new)?;
                rows.extend(new);
                pb.inc(todo.len() as u64);
            }
            Err(e) => {
                tracing::error!("policy {name}: {e:#}; continuing with the other policies");
                failed.push(json!({"policy": name, "error": format!("{e:#}")}));
            }
        }
        Ok(())
    };
    let timing = schedule::run_batches(&policies, &jobs, &setup, &wm, a.jobs, &mut done)?;
    pb.finish_and_clear();
    let failed_names: Vec<&str> = failed.iter().filter_map(|f| f["policy"].as_str()).collect();
    let ok_names: Vec<String> =
        names.iter().filter(|n| !failed_names.contains(&n.as_str())).cloned().collect();
    let mut res = summarise(&rows, &ok_names, a.bootstrap, a.seed);
    let wall = started.elapsed().as_secs_f64();
    res["scenario"] = json!(a.scenario);
    res["world_model"] = json!(a.world_model);
    res["episodes"] = json!(a.episodes);
    res["seed_start"] = json!(a.seed_start);
    res["max_steps"] = json!(a.max_steps);
    res["failed_policies"] = json!(failed);
    res["timing"] = json!({
        "wall_seconds": wall,
        "sim_seconds": timing.sim_s,
        "world_model_seconds": timing.world_model_s,
        "world_model_ms_per_frame": 1e3 * timing.world_model_s / timing.frames.max(1) as f64,
        "policy_seconds": timing.policy_s,
        "note": "this session only (a resumed run times its own part)",
    });
    write_json(&a.out.join("results.json"), &res)?;
    write_tables(&a.out, &rows)?;
    if !a.no_report {
        if shards == 1 {
            rollouts(a, &dirs, &rows, &failed_names, &setup, &wm, &pool)?;
        }
        let html = report::write_report(&a.out)?;
        tracing::info!(report = %html.display(), "report written");
    }
    if let Some((text, true)) = scene::scene_note(&res) {
        tracing::warn!("{text}");
    }
    print_summary(&res, &a.out);
    gates(a, &res, &failed)
}

/// Loads the world model in `dir`, with `--alpha` applied when given.
///
/// # Errors
/// An unloadable model, or an α it cannot take, naming the folder.
pub(crate) fn load_world_model(
    dir: &Path,
    alpha: Option<f32>,
    device: &burn::tensor::Device,
) -> Result<WorldModel> {
    let mut wm =
        WorldModel::load(dir, device).with_context(|| format!("loading world model {}", dir.display()))?;
    if let Some(alpha) = alpha {
        wm.set_alpha(alpha).map_err(|e| anyhow::anyhow!("--alpha: {e} ({})", dir.display()))?;
    }
    Ok(wm)
}

/// Replays each policy's best- and worst-agreeing episodes with frame recording.
fn rollouts(
    a: &RankArgs,
    dirs: &[std::path::PathBuf],
    rows: &[EpisodeRow],
    failed: &[&str],
    setup: &Setup,
    wm: &WorldModel,
    pool: &rayon::ThreadPool,
) -> Result<()> {
    let dir = a.out.join("filmstrips");
    let device = wm.device().clone();
    let expect = Expectations { image_size: setup.cfg.render.size as usize, action_dim: 2 };
    let mut index = Vec::new();
    for d in dirs {
        let name = checkpoint_name(d);
        if failed.contains(&name.as_str()) {
            continue;
        }
        let Ok(policy) = load_any(d, expect, &device, setup.cfg, setup.model) else { continue };
        let picks = media::pick_seeds(rows, &name);
        let strips = pool.install(|| media::write_rollouts(&dir, policy.as_ref(), &picks, setup, wm, 4))?;
        for (png, caption) in strips {
            let file = png.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
            index.push(json!({"png": file, "caption": caption}));
        }
    }
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    write_json(&dir.join("index.json"), &Value::Array(index))
}

/// Exit 1 when a gate fails (or a policy failed), 0 otherwise.
fn gates(a: &RankArgs, res: &Value, failed: &[Value]) -> Result<ExitCode> {
    let mut ok = true;
    if let Some(min) = a.min_pearson {
        let r = res["agreement"]["pearson"].as_f64();
        if r.is_none_or(|r| r < min) {
            eprintln!("gate failed: Pearson {r:?} < --min-pearson {min}");
            ok = false;
        }
    }
    if let Some(max) = a.max_inversions {
        let k = res["agreement"]["rank_inversions"].as_u64().unwrap_or(u64::MAX);
        if k > max {
            eprintln!("gate failed: {k} rank inversions > --max-inversions {max}");
            ok = false;
        }
    }
    if !failed.is_empty() {
        eprintln!("{} policies failed (see results.json \"failed_policies\")", failed.len());
        ok = false;
    }
    Ok(if ok { ExitCode::SUCCESS } else { ExitCode::from(1) })
}

/// Writes `episodes.csv` and `episodes.parquet` into `out`: the rows sorted by
/// (policy, seed, branch).
pub(crate) fn write_tables(out: &Path, rows: &[EpisodeRow]) -> Result<()> {
    let mut sorted: Vec<&EpisodeRow> = rows.iter().collect();
    sorted.sort_by(|x, y| (&x.policy, x.seed, x.branch).cmp(&(&y.policy, y.seed, y.branch)));
    write_csv(&out.join("episodes.csv"), &sorted)?;
    let records: Vec<EpisodeRecord> = sorted
        .iter()
        .map(|r| EpisodeRecord {
            policy: r.policy.clone(),
            seed: r.seed,
            branch: r.branch.as_str().to_string(),
            score: r.score,
            max_coverage: r.max_coverage,
            final_coverage: r.final_coverage,
            success: r.success,
            steps: r.steps as u32,
            final_block: r.final_block,
            goal: r.goal,
            scorer_abs_error: r.scorer_abs_error,
            block_area: r.block_area,
            goal_kept: r.goal_kept,
            agent_kept: r.agent_kept,
        })
        .collect();
    write_episodes_parquet(&out.join("episodes.parquet"), &records)?;
    Ok(())
}

fn write_csv(path: &Path, sorted: &[&EpisodeRow]) -> Result<()> {
    let mut w = csv::Writer::from_path(path).with_context(|| format!("creating {}", path.display()))?;
    w.write_record([
        "policy",
        "seed",
        "branch",
        "score",
        "max_coverage",
        "final_coverage",
        "success",
        "steps",
    ])?;
    for r in sorted {
        let branch = r.branch.as_str().to_string();
        w.write_record([
            r.policy.clone(),
            r.seed.to_string(),
            branch,
            format!("{:.6}", r.score),
            format!("{:.6}", r.max_coverage),
            format!("{:.6}", r.final_coverage),
            r.success.to_string(),
            r.steps.to_string(),
        ])?;
    }
    w.flush().with_context(|| format!("writing {}", path.display()))
}

fn print_summary(res: &Value, out: &Path) {
    println!(
        "{:<16} {:>10} {:>12} {:>12} {:>10} {:>11}",
        "policy", "MuJoCo", "world model", "block kept", "goal kept", "agent kept"
    );
    for p in res["policies"].as_array().into_iter().flatten() {
        let wm = |k: &str| p["world_model"][k].as_f64().unwrap_or(f64::NAN);
        println!(
            "{:<16} {:>10.3} {:>12.3} {:>12.2} {:>10.2} {:>11.2}",
            p["name"].as_str().unwrap_or("?"),
            p["sim"]["mean"].as_f64().unwrap_or(f64::NAN),
            wm("mean"),
            wm("block_area"),
            wm("goal_kept"),
            wm("agent_kept")
        );
    }
    let ag = &res["agreement"];
    let f = |k: &str| ag[k].as_f64().map_or("n/a".to_string(), |v| format!("{v:.3}"));
    println!(
        "Pearson {}  Spearman {}  Kendall tau_b {}  inversions {}  MMRV {}  regret@1 {}",
        f("pearson"),
        f("spearman"),
        f("kendall_tau_b"),
        ag["rank_inversions"],
        f("mmrv"),
        f("regret_at_1")
    );
    println!("results: {}", out.join("results.json").display());
}
