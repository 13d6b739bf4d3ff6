//! `evalharness merge SHARD... --out OUT`: joins `rank --shard i/n` outputs into
//! what one unsharded run writes — the same `episodes.jsonl` rows in the same
//! order (policy, seed, branch), hence the same `results.json` (timings are summed).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Result, bail};
use serde_json::{Value, json};

use harness::results::{FailedPolicy, RankResults, RunTiming};

use crate::output::{Staged, read_json, write_json};
use harness::results::EpisodeRow;
use harness::rows::{append_rows, read_rows};
use harness::summarise::summarise;

/// The run-defining part of a config (everything but the shard and the command).
fn run_key(cfg: &Value) -> Value {
    let mut c = cfg.clone();
    if let Some(o) = c.as_object_mut() {
        o.remove("shard");
        o.remove("command");
    }
    c
}

/// Checks that the shards are exactly one complete set: `rank --shard i/n` outputs
/// with the same n, every i from 0 to n − 1 once. A missing shard would leave
/// policies with too few episodes, a repeated one count nothing twice but hide the
/// missing one.
///
/// # Errors
/// A folder without a valid `shard` in its config, counts that differ, or an index
/// missing or repeated, naming the folders.
fn check_complete_set(shards: &[PathBuf], configs: &[Value]) -> Result<()> {
    let mut seen: Vec<Option<&PathBuf>> = Vec::new();
    let mut n_first: Option<(u64, &PathBuf)> = None;
    for (s, cfg) in shards.iter().zip(configs) {
        let (Some(i), Some(n)) = (cfg["shard"][0].as_u64(), cfg["shard"][1].as_u64()) else {
            bail!("{}: config.json has no \"shard\": [i, n] (not a rank output)", s.display());
        };
        match n_first {
            None => {
                n_first = Some((n, s));
                seen = vec![None; n as usize];
            }
            Some((n0, s0)) if n0 != n => {
                bail!(
                    "{} is shard {i}/{n} but {} is one of {n0}: not shards of one split",
                    s.display(),
                    s0.display()
                )
            }
            Some(_) => {}
        }
        let Some(slot) = seen.get_mut(i as usize) else {
            bail!("{}: shard {i}/{n} is out of range", s.display());
        };
        if let Some(other) = slot {
            bail!("{} and {} are both shard {i}/{n}; give each shard once", other.display(), s.display());
        }
        *slot = Some(s);
    }
    let missing: Vec<String> =
        seen.iter().enumerate().filter(|(_, s)| s.is_none()).map(|(i, _)| i.to_string()).collect();
    if !missing.is_empty() {
        let n = seen.len();
        bail!("shard {} of {n} missing: a merge needs all {n} shards of the run", missing.join(", "));
    }
    Ok(())
}

/// Refuses joined rows that lack a row of some (policy, seed, branch) of the run: a
/// shard killed before it finished a batch, or a claim whose batch nobody ran, would
/// otherwise give a result over fewer episodes than the run says. Policies that failed
/// (reported in `failed_policies`) are exempt.
///
/// # Errors
/// The first policy with missing rows, naming it and up to five seeds.
fn check_every_row(
    rows: &[EpisodeRow],
    names: &[String],
    failed: &[FailedPolicy],
    cfg: &Value,
) -> Result<()> {
    let (Some(start), Some(n)) = (cfg["seed_start"].as_u64(), cfg["episodes"].as_u64()) else {
        bail!("the shards' config.json has no seed_start and episodes (not a rank output)");
    };
    let seeds = harness::seed::range(start, n)?;
    let mut have: std::collections::HashSet<(&str, u64, harness::results::Branch)> =
        std::collections::HashSet::with_capacity(rows.len());
    for r in rows {
        have.insert((r.policy.as_str(), r.seed, r.branch));
    }
    for name in names.iter().filter(|n| !failed.iter().any(|f| &f.policy == *n)) {
        let missing: Vec<u64> = seeds
            .clone()
            .filter(|&s| super::resume::RANK_KINDS.iter().any(|&b| !have.contains(&(name.as_str(), s, b))))
            .collect();
        if !missing.is_empty() {
            let shown: Vec<String> = missing.iter().take(5).map(u64::to_string).collect();
            bail!(
                "policy {name} lacks rows of {} of its {n} seeds ({}{}): a shard did not finish its \
                 batches; resume the shards (rank --shard i/n --resume, or rank --processes N --resume) \
                 and merge again",
                missing.len(),
                shown.join(", "),
                if missing.len() > 5 { ", ..." } else { "" }
            );
        }
    }
    Ok(())
}

/// `evalharness merge`: joins shard folders into `out` and says so on stdout.
///
/// # Errors
/// As [`join`].
pub fn run(shards: &[PathBuf], out: &Path, force: bool, no_report: bool) -> Result<ExitCode> {
    let (rows, _) = join(shards, out, force, no_report, true)?;
    outln!("merged {} shards: {rows} rows -> {}", shards.len(), out.display());
    Ok(ExitCode::SUCCESS)
}

/// Joins shard folders into `out` (written into `OUT.partial`, moved into place when
/// complete); returns the number of rows and the shards' timing, summed. With
/// `complete`, every ranked policy must have both rows of every seed (the `merge`
/// command's contract); without, a batch no shard finished is left for the finishing
/// `--resume` run to do (`rank --processes`).
///
/// # Errors
/// Missing files, shards of different runs, duplicate rows that disagree, missing
/// rows (with `complete`), or I/O failures.
pub(super) fn join(
    shards: &[PathBuf],
    out: &Path,
    force: bool,
    no_report: bool,
    complete: bool,
) -> Result<(usize, RunTiming)> {
    if shards.is_empty() {
        bail!("give at least one shard folder");
    }
    let listed = crate::output::Inputs::new().all("shard", shards);
    listed.check(out)?;
    let configs: Vec<Value> =
        shards.iter().map(|s| read_json(&s.join("config.json"))).collect::<Result<_>>()?;
    let first = &configs[0];
    let key = run_key(first);
    check_complete_set(shards, &configs)?;
    let mut rows: Vec<EpisodeRow> = Vec::new();
    let mut failed: Vec<FailedPolicy> = Vec::new();
    let mut timing = RunTiming {
        wall_seconds: 0.0,
        sim_seconds: 0.0,
        world_model_seconds: 0.0,
        world_model_ms_per_frame: 0.0,
        policy_seconds: 0.0,
        note: format!("summed over {} shards", shards.len()),
    };
    let mut frames = 0.0;
    let mut first_res: Option<RankResults> = None;
    for (s, cfg) in shards.iter().zip(&configs) {
        let this = run_key(cfg);
        if this != key {
            let names = |v: &Value| -> std::collections::BTreeSet<String> {
                v.as_object().into_iter().flatten().map(|(k, _)| k.clone()).collect()
            };
            let differs: Vec<String> = names(&this)
                .union(&names(&key))
                .filter(|k| this.get(k.as_str()) != key.get(k.as_str()))
                .cloned()
                .collect();
            bail!(
                "{}: not a shard of the same run as {} (they differ in {})",
                s.display(),
                shards[0].display(),
                differs.join(", ")
            );
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
        let res = RankResults::read(&s.join("results.json"))?;
        for f in &res.failed_policies {
            if !failed.contains(f) {
                failed.push(f.clone());
            }
        }
        let t = &res.timing;
        timing.wall_seconds += t.wall_seconds;
        timing.sim_seconds += t.sim_seconds;
        timing.world_model_seconds += t.world_model_seconds;
        timing.policy_seconds += t.policy_seconds;
        if t.world_model_ms_per_frame > 0.0 {
            frames += t.world_model_seconds * 1e3 / t.world_model_ms_per_frame;
        }
        first_res.get_or_insert(res);
    }
    let Some(first_res) = first_res else { bail!("give at least one shard folder") };
    timing.world_model_ms_per_frame = 1e3 * timing.world_model_seconds / frames.max(1.0);
    let names: Vec<String> = first["checkpoints"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_str)
        .map(|c| Path::new(c).file_name().map_or_else(|| c.to_string(), |n| n.to_string_lossy().into_owned()))
        .collect();
    let order = |p: &str| names.iter().position(|n| n == p).unwrap_or(usize::MAX);
    rows.sort_by_key(|r| (order(&r.policy), r.seed, r.branch));
    if complete {
        check_every_row(&rows, &names, &failed, first)?;
    }
    // Everything is written into OUT.partial and moved into place at the end.
    let staged = Staged::new(out, force, &listed)?;
    let tmp = staged.dir().to_path_buf();
    append_rows(&tmp.join("episodes.jsonl"), &rows)?;
    let failed_names: Vec<&str> = failed.iter().map(|f| f.policy.as_str()).collect();
    let ok: Vec<String> = names.iter().filter(|n| !failed_names.contains(&n.as_str())).cloned().collect();
    let bootstrap = first["bootstrap"].as_u64().unwrap_or(2000) as usize;
    let (policies, agreement) = summarise(&rows, &ok, bootstrap, first["seed"].as_u64().unwrap_or(0));
    let res = RankResults { policies, agreement, failed_policies: failed, timing, ..first_res };
    write_json(&tmp.join("results.json"), &res.to_json()?)?;
    let mut cfg = first.clone();
    cfg["shard"] = json!([0, 1]);
    cfg["merged_from"] = json!(shards);
    write_json(&tmp.join("config.json"), &cfg)?;
    super::write_tables(&tmp, &rows)?;
    if !no_report {
        super::report::write_report(&tmp)?;
    }
    staged.commit()?;
    Ok((rows.len(), res.timing))
}
