//! `merge`'s work: `rank --shard i/n` folders joined into what one unsharded run
//! writes — the same `episodes.jsonl` rows in the same order (policy, seed, branch),
//! hence the same `results.json` (timings are summed) — staged in `OUT.partial` and
//! moved into place when complete.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use harness::results::{Branch, EpisodeRow, FailedPolicy, RankResults, RunTiming};
use harness::rows::{append_rows, read_rows};
use harness::summarise::summarise;

use crate::config::RankConfig;
use crate::error::RunError;
use crate::output::{Inputs, Staged};

/// Joins shard folders into `out` (written into `OUT.partial`, moved into place when
/// complete); returns the number of rows and the shards' timing, summed. With
/// `complete`, every ranked policy must have both rows of every seed (the `merge`
/// command's contract); without, a batch no shard finished is left for the finishing
/// `--resume` run to do (`rank --processes`).
///
/// # Errors
/// Missing files, shards of different runs, duplicate rows that disagree, missing
/// rows (with `complete`), or I/O failures.
pub fn join(
    shards: &[PathBuf],
    out: &Path,
    force: bool,
    no_report: bool,
    complete: bool,
) -> Result<(usize, RunTiming), RunError> {
    let none = || RunError::Shards("give at least one shard folder".into());
    if shards.is_empty() {
        return Err(none());
    }
    let listed = Inputs::new().all("shard", shards);
    listed.check(out)?;
    let configs: Vec<RankConfig> =
        shards.iter().map(|s| crate::config::read(&s.join("config.json"))).collect::<Result<_, _>>()?;
    crate::shards::check_complete_set(shards, &configs)?;
    let first = &configs[0];
    let mut rows: Vec<EpisodeRow> = Vec::new();
    // Where each (policy, seed, branch) is in `rows`: a row two shards both hold must be
    // the same row.
    let mut at: HashMap<(String, u64, Branch), usize> = HashMap::new();
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
    for s in shards {
        for r in read_rows::<EpisodeRow>(&s.join("episodes.jsonl"))? {
            match at.get(&(r.policy.clone(), r.seed, r.branch)) {
                Some(&i) if rows[i] != r => {
                    return Err(RunError::Shards(format!(
                        "{}: policy {} seed {} differs between shards",
                        s.display(),
                        r.policy,
                        r.seed
                    )));
                }
                Some(_) => {}
                None => {
                    at.insert((r.policy.clone(), r.seed, r.branch), rows.len());
                    rows.push(r);
                }
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
    let first_res = first_res.ok_or_else(none)?;
    timing.world_model_ms_per_frame = 1e3 * timing.world_model_seconds / frames.max(1.0);
    let names = first.policy_names();
    let order = |p: &str| names.iter().position(|n| n == p).unwrap_or(usize::MAX);
    rows.sort_by_key(|r| (order(&r.policy), r.seed, r.branch));
    if complete {
        crate::shards::check_every_row(&rows, &failed, first)?;
    }
    // Everything is written into OUT.partial and moved into place at the end.
    let staged = Staged::new(out, force, &listed)?;
    let tmp = staged.dir().to_path_buf();
    append_rows(&tmp.join("episodes.jsonl"), &rows)?;
    let failed_names: Vec<&str> = failed.iter().map(|f| f.policy.as_str()).collect();
    let ok: Vec<String> = names.iter().filter(|n| !failed_names.contains(&n.as_str())).cloned().collect();
    let (policies, agreement) = summarise(&rows, &ok, first.bootstrap, first.seed);
    // Written in this build's layout, whichever version the shards were written in.
    let schema_version = harness::results::RESULTS_SCHEMA;
    let res =
        RankResults { schema_version, policies, agreement, failed_policies: failed, timing, ..first_res };
    // As `rank` writes it: the struct as a JSON value (its keys sorted).
    let results = tmp.join("results.json");
    let value = res.to_json().map_err(|e| RunError::File {
        doing: format!("writing {}", results.display()),
        source: std::io::Error::other(e),
    })?;
    crate::config::write(&results, &value)?;
    crate::config::write(&tmp.join("config.json"), &crate::shards::joined(first, shards))?;
    reports::episode_tables::write_tables(&tmp, &rows)?;
    if !no_report {
        crate::report::write_report(&tmp)?;
    }
    staged.commit()?;
    Ok((rows.len(), res.timing))
}
