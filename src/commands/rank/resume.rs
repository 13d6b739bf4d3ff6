//! What `rank --resume` (and `plan --resume`) accepts: the same run continued, or a finished run grown to
//! more episodes per policy. Anything else would mix the rows of two experiments in
//! one `episodes.jsonl`, so it is refused with each differing setting named.

use std::path::Path;

use anyhow::{Result, bail};
use serde_json::Value;

use crate::output::read_json;
use harness::results::{Branch, EpisodeRow};

/// Settings a resumed run may change: the command line itself, the bootstrap count (the
/// statistics are recomputed from all rows), and `merged_from`, the provenance `merge` adds
/// (which shards a run was joined from).
const FREE_ON_RESUME: [&str; 3] = ["command", "bootstrap", "merged_from"];

/// Refuses to resume a run under different settings (seeds, policies, world model and
/// its α, batch size, ...). The batch size counts because the kernels' float rounding
/// depends on the matrix shapes, so an episode run in a batch of another size can come
/// out slightly different, and a resumed run would no longer equal a straight one bit
/// for bit.
///
/// `--episodes` may grow (never shrink): the seeds are `seed_start ..
/// seed_start + episodes` cut into batches from the first, so when the saved count is
/// a whole number of batches, the new seeds form batches of their own, exactly the
/// ones a straight run of the larger count has. A count that ends in a part batch, or
/// a sharded run (whose share of the batches depends on their number), cannot grow
/// that way and is refused. The content fingerprints of the models must match. A
/// folder without a saved config resumes only when it holds no rows either (the
/// caller refuses rows without settings).
pub(crate) fn check_config(path: &Path, config: &Value) -> Result<()> {
    if !path.is_file() {
        return Ok(());
    }
    let saved = read_json(path)?;
    check_fingerprints(path, &saved, config)?;
    // Every setting either side has: one the saved run recorded and this one lacks (a
    // `--judge` left out, say) differs as much as one with another value.
    let keys: std::collections::BTreeSet<&str> = [config, &saved]
        .into_iter()
        .filter_map(Value::as_object)
        .flat_map(|m| m.keys().map(String::as_str))
        .collect();
    let differs: Vec<String> = keys
        .into_iter()
        .filter(|k| !FREE_ON_RESUME.contains(k) && *k != "episodes" && *k != "fingerprints")
        .filter(|k| saved.get(*k) != config.get(*k))
        .map(|k| {
            let show = |v: Option<&Value>| v.map_or("absent".to_string(), short);
            format!("{k} (saved: {}, now: {})", show(saved.get(k)), show(config.get(k)))
        })
        .collect();
    if !differs.is_empty() {
        bail!(
            "--resume: {} was written with other settings: {}; pass the same options, or --force to start over",
            path.display(),
            differs.join("; ")
        );
    }
    check_growth(path, &saved, config)
}

/// Refuses to resume when a model folder's content changed since the saved run (new
/// weights under the same name would be mixed with the old ones' rows), naming each.
fn check_fingerprints(path: &Path, saved: &Value, config: &Value) -> Result<()> {
    let Some(now) = config.get("fingerprints").and_then(Value::as_object) else { return Ok(()) };
    let Some(was) = saved.get("fingerprints").and_then(Value::as_object) else {
        bail!(
            "--resume: {} records no fingerprints of its models, so it cannot be checked that \
             they are unchanged; start a new run (--force or another --out)",
            path.display()
        );
    };
    let changed: Vec<&str> = now
        .iter()
        .filter(|(k, v)| was.get(k.as_str()).is_some_and(|w| w != *v))
        .map(|(k, _)| k.as_str())
        .collect();
    if !changed.is_empty() {
        bail!(
            "--resume: the content of {} changed since {} was written (its rows came from the \
             old files); restore them, or start a new run (--force or another --out)",
            changed.join(", "),
            path.display()
        );
    }
    Ok(())
}

/// Puts a resumed or extended run's rows in the order a straight run appends them
/// (policy by policy in folder order, each policy's batches in seed order; rows within
/// a batch as the engine gave them), rewriting `episodes.jsonl` atomically when the
/// order changed. A run grown with `--episodes` appended its new batches after every
/// policy's old ones; sorted, its file equals the straight run's byte for byte.
///
/// # Errors
/// The file cannot be written.
pub(crate) fn straight_order(
    jsonl: &Path,
    rows: &mut [EpisodeRow],
    names: &[String],
    batches: &[&[u64]],
) -> Result<()> {
    let batch_of = |seed: u64| batches.iter().position(|b| b.contains(&seed)).unwrap_or(usize::MAX);
    let key =
        |r: &EpisodeRow| (names.iter().position(|n| *n == r.policy).unwrap_or(usize::MAX), batch_of(r.seed));
    if rows.windows(2).all(|w| key(&w[0]) <= key(&w[1])) {
        return Ok(());
    }
    rows.sort_by_key(key);
    let mut text = String::new();
    for r in rows.iter() {
        text.push_str(&serde_json::to_string(r)?);
        text.push('\n');
    }
    harness::runfile::write_atomic(jsonl, &text)
        .map_err(|e| anyhow::anyhow!("rewriting {} in run order: {}", e.path.display(), e.message))
}

/// A `rank` row's (policy, seed, branch), for [`harness::rows::whole_batches`].
pub(crate) fn rank_key(r: &EpisodeRow) -> (&str, u64, Branch) {
    (r.policy.as_str(), r.seed, r.branch)
}

/// The rows each seed of a whole `rank` batch has: one per branch.
pub(crate) const RANK_KINDS: [Branch; 2] = [Branch::Sim, Branch::WorldModel];

/// The `--episodes` rule of [`check_config`] (the other settings already agree).
fn check_growth(path: &Path, saved: &Value, config: &Value) -> Result<()> {
    let (was, now) = (saved["episodes"].as_u64(), config["episodes"].as_u64());
    if was == now {
        return Ok(());
    }
    let (Some(was), Some(now)) = (was, now) else {
        bail!("--resume: {} has no valid \"episodes\" ({})", path.display(), saved["episodes"]);
    };
    if now < was {
        bail!(
            "--resume: {} holds a run of {was} episodes per policy, and --episodes {now} would drop \
             some; pass --episodes {was} (or more, to extend it)",
            path.display()
        );
    }
    let batch = config["batch"].as_u64().unwrap_or(1).max(1);
    if was % batch != 0 {
        bail!(
            "--resume --episodes {now}: the saved run's {was} episodes end in a part batch of \
             --batch {batch}, which a straight run of {now} would fill with other seeds (and \
             round differently), so this run cannot be extended bit for bit; start a new one \
             (--force or another --out), or run the extra seeds with --seed-start {}",
            saved["seed_start"].as_u64().unwrap_or(0) + was
        );
    }
    if config.get("shard").is_some_and(|s| *s != serde_json::json!([0, 1])) {
        bail!(
            "--resume --episodes {now}: {} is one shard of a run, and a shard's share of the \
             batches changes with their number; extend the merged run instead",
            path.display()
        );
    }
    tracing::info!(from = was, to = now, "extending the run: only the new seeds are run");
    Ok(())
}

/// A setting's value for an error message, cut at 60 characters.
fn short(v: &Value) -> String {
    let text = v.to_string();
    if text.chars().count() > 60 { format!("{}…", text.chars().take(60).collect::<String>()) } else { text }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn saved(dir: &Path, episodes: u64, shard: [u64; 2]) -> std::path::PathBuf {
        let path = dir.join("config.json");
        let cfg = json!({"command": "rank", "episodes": episodes, "batch": 50, "seed_start": 100,
            "shard": shard, "bootstrap": 2000});
        std::fs::write(&path, cfg.to_string()).unwrap();
        path
    }

    fn now(episodes: u64, shard: [u64; 2]) -> Value {
        json!({"command": "rank --resume", "episodes": episodes, "batch": 50, "seed_start": 100,
            "shard": shard, "bootstrap": 100})
    }

    #[test]
    fn a_finished_run_of_whole_batches_grows() {
        let dir = tempfile::tempdir().unwrap();
        let path = saved(dir.path(), 100, [0, 1]);
        check_config(&path, &now(100, [0, 1])).unwrap();
        check_config(&path, &now(250, [0, 1])).unwrap();
    }

    #[test]
    fn shrinking_a_part_batch_and_a_shard_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = saved(dir.path(), 100, [0, 1]);
        let err = check_config(&path, &now(60, [0, 1])).unwrap_err().to_string();
        assert!(err.contains("--episodes 60 would drop"), "{err}");
        // 120 = 2 whole batches of 50 and a part batch of 20: seeds 100..220 would be
        // batched 100..150, 150..200, 200..250 by a straight run of 150.
        let path = saved(dir.path(), 120, [0, 1]);
        let err = check_config(&path, &now(150, [0, 1])).unwrap_err().to_string();
        assert!(err.contains("part batch") && err.contains("--seed-start 220"), "{err}");
        let path = saved(dir.path(), 100, [1, 2]);
        let err = check_config(&path, &now(200, [1, 2])).unwrap_err().to_string();
        assert!(err.contains("one shard"), "{err}");
    }

    fn row(policy: &str, seed: u64, branch: Branch) -> EpisodeRow {
        EpisodeRow::new(policy, seed, branch, 0.5, 0.5, 0.5, 0.95, 10)
    }

    #[test]
    fn only_whole_batches_are_kept() {
        // Seeds 10..14 in batches [10, 11], [12, 13]. Policy a: batch 0 whole, batch 1
        // lacks seed 13's world-model row; policy b: batch 0 has seed 10's MuJoCo row
        // twice; seed 99 is outside the run.
        let batches: Vec<&[u64]> = vec![&[10, 11], &[12, 13]];
        let (s, w) = (Branch::Sim, Branch::WorldModel);
        let rows = vec![
            row("a", 10, s),
            row("a", 10, w),
            row("a", 11, s),
            row("a", 11, w),
            row("a", 12, s),
            row("a", 12, w),
            row("a", 13, s),
            row("b", 10, s),
            row("b", 10, s),
            row("b", 10, w),
            row("b", 11, s),
            row("b", 11, w),
            row("a", 99, s),
        ];
        let keep = harness::rows::whole_batches(&rows, &batches, rank_key, &RANK_KINDS);
        assert_eq!(
            keep,
            [true, true, true, true, false, false, false, false, false, false, false, false, false]
        );
    }

    #[test]
    fn changed_model_content_is_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("config.json");
        let mut cfg = now(100, [0, 1]);
        cfg["fingerprints"] = json!({"world_model": "sha256:aa", "policy p": "sha256:bb"});
        std::fs::write(&path, cfg.to_string()).unwrap();
        check_config(&path, &cfg).unwrap();
        let mut other = cfg.clone();
        other["fingerprints"]["policy p"] = json!("sha256:cc");
        let err = check_config(&path, &other).unwrap_err().to_string();
        assert!(err.contains("content of policy p changed"), "{err}");
        // A run saved before fingerprints were recorded cannot be checked: refused.
        std::fs::write(&path, now(100, [0, 1]).to_string()).unwrap();
        let err = check_config(&path, &cfg).unwrap_err().to_string();
        assert!(err.contains("records no fingerprints"), "{err}");
    }

    #[test]
    fn other_settings_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = saved(dir.path(), 100, [0, 1]);
        let mut other = now(200, [0, 1]);
        other["seed_start"] = json!(7);
        let err = check_config(&path, &other).unwrap_err().to_string();
        assert!(err.contains("seed_start (saved: 100, now: 7)") && !err.contains("episodes"), "{err}");
    }
}
