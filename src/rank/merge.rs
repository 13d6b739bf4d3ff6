//! `evalharness merge SHARD... --out OUT`: joins `rank --shard i/n` outputs into
//! what one unsharded run writes — the same `episodes.jsonl` rows in the same
//! order (policy, seed, branch), hence the same `results.json` (timings are summed).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use serde_json::{Value, json};

use super::results::{EpisodeRow, append_rows, read_rows, summarise};
use crate::output::{read_json, write_json};

/// The run-defining part of a config (everything but the shard and the command).
fn run_key(cfg: &Value) -> Value {
    let mut c = cfg.clone();
    if let Some(o) = c.as_object_mut() {
        o.remove("shard");
        o.remove("command");
    }
    c
}

/// Merges shard folders into `out`.
///
/// # Errors
/// Missing files, shards of different runs, duplicate rows that disagree, or I/O failures.
pub fn run(shards: &[PathBuf], out: &Path, force: bool, no_report: bool) -> Result<ExitCode> {
    if shards.is_empty() {
        bail!("give at least one shard folder");
    }
    if out.exists() {
        if !force {
            bail!("{} already exists (pass --force to replace it)", out.display());
        }
        std::fs::remove_dir_all(out).with_context(|| format!("removing {}", out.display()))?;
    }
    let first = read_json(&shards[0].join("config.json"))?;
    let key = run_key(&first);
    let mut rows: Vec<EpisodeRow> = Vec::new();
    let (mut failed, mut timing) = (Vec::<Value>::new(), [0.0f64; 5]);
    let mut frames = 0.0;
    for s in shards {
        let cfg = read_json(&s.join("config.json"))?;
        if run_key(&cfg) != key {
            bail!("{}: not a shard of the same run as {}", s.display(), shards[0].display());
        }
        for r in read_rows::<EpisodeRow>(&s.join("episodes.jsonl"))? {
            match rows.iter().find(|x| x.policy == r.policy && x.seed == r.seed && x.branch == r.branch) {
                Some(x) if *x != r => {
                    bail!("{}: policy {} seed {} differs between shards", s.display(), r.policy, r.seed)
                }
                Some(_) => {}
                None => rows.push(r),
            }
        }
        let res = read_json(&s.join("results.json"))?;
        for f in res["failed_policies"].as_array().into_iter().flatten() {
            if !failed.contains(f) {
                failed.push(f.clone());
            }
        }
        let t = &res["timing"];
        for (acc, k) in timing.iter_mut().zip([
            "wall_seconds",
            "sim_seconds",
            "world_model_seconds",
            "policy_seconds",
            "world_model_ms_per_frame",
        ]) {
            *acc += t[k].as_f64().unwrap_or(0.0);
        }
        frames += t["world_model_seconds"].as_f64().unwrap_or(0.0) * 1e3
            / t["world_model_ms_per_frame"].as_f64().filter(|v| *v > 0.0).unwrap_or(f64::INFINITY);
    }
    let names: Vec<String> = first["checkpoints"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_str)
        .map(|c| Path::new(c).file_name().map_or_else(|| c.to_string(), |n| n.to_string_lossy().into_owned()))
        .collect();
    let order = |p: &str| names.iter().position(|n| n == p).unwrap_or(usize::MAX);
    rows.sort_by_key(|r| (order(&r.policy), r.seed, r.branch));
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    append_rows(&out.join("episodes.jsonl"), &rows)?;
    let failed_names: Vec<&str> = failed.iter().filter_map(|f| f["policy"].as_str()).collect();
    let ok: Vec<String> = names.iter().filter(|n| !failed_names.contains(&n.as_str())).cloned().collect();
    let bootstrap = first["bootstrap"].as_u64().unwrap_or(2000) as usize;
    let mut res = summarise(&rows, &ok, bootstrap, first["seed"].as_u64().unwrap_or(0));
    for k in ["scenario", "world_model", "episodes", "seed_start", "max_steps"] {
        res[k] = first[k].clone();
    }
    res["failed_policies"] = json!(failed);
    res["timing"] = json!({
        "wall_seconds": timing[0], "sim_seconds": timing[1], "world_model_seconds": timing[2],
        "world_model_ms_per_frame": 1e3 * timing[2] / frames.max(1.0), "policy_seconds": timing[3],
        "note": format!("summed over {} shards", shards.len()),
    });
    write_json(&out.join("results.json"), &res)?;
    let mut cfg = first.clone();
    cfg["shard"] = json!([0, 1]);
    cfg["merged_from"] = json!(shards);
    write_json(&out.join("config.json"), &cfg)?;
    super::write_tables(out, &rows)?;
    if !no_report {
        super::report::write_report(out)?;
    }
    println!("merged {} shards: {} rows -> {}", shards.len(), rows.len(), out.display());
    Ok(ExitCode::SUCCESS)
}
