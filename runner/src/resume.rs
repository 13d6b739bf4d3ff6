//! What `rank --resume` and `plan --resume` accept: the same run continued, or a
//! finished run grown to more episodes per policy. Anything else would mix the rows of
//! two experiments in one `episodes.jsonl`, so it is refused with each differing
//! setting named. And the order a resumed run's rows are left in: a straight run's.

use std::path::Path;

use harness::results::{Branch, EpisodeRow};

use crate::config::{RunSettings, differing, read};
use crate::error::RunError;

/// Settings a resumed run may change: the bootstrap count (the statistics are
/// recomputed from all rows), `merged_from` (the provenance `merge` adds), the episode
/// count (by [`check`]'s growth rule) and the fingerprints (by their own rule). The
/// command line is not a setting.
const FREE_ON_RESUME: [&str; 4] = ["bootstrap", "merged_from", "episodes", "fingerprints"];

/// Refuses to resume the run whose saved configuration is `path` under the settings
/// `now` when they differ (seeds, policies, world model and its α, batch size, ...).
/// The batch size counts because the kernels' float rounding depends on the matrix
/// shapes, so an episode run in a batch of another size can come out slightly
/// different, and a resumed run would no longer equal a straight one bit for bit.
///
/// `--episodes` may grow (never shrink): the seeds are `seed_start .. seed_start +
/// episodes` cut into batches from the first, so when the saved count is a whole
/// number of batches, the new seeds form batches of their own, exactly the ones a
/// straight run of the larger count has. A count that ends in a part batch, or a
/// sharded run (whose share of the batches depends on their number), cannot grow that
/// way and is refused. The content fingerprints of the inputs both runs name must
/// match. A folder without a saved configuration resumes only when it holds no rows
/// either (the caller refuses rows without settings).
///
/// # Errors
/// A [`RunError`] naming the file and what differs.
pub fn check<C: RunSettings>(path: &Path, now: &C) -> Result<(), RunError> {
    if !path.is_file() {
        return Ok(());
    }
    let saved: C = read(path)?;
    let changed: Vec<String> = now
        .fingerprints()
        .iter()
        .filter(|(k, v)| saved.fingerprints().get(*k).is_some_and(|w| w != *v))
        .map(|(k, _)| k.clone())
        .collect();
    if !changed.is_empty() {
        return Err(RunError::Changed { path: path.to_path_buf(), names: changed });
    }
    let differs = differences(&saved, now, &FREE_ON_RESUME);
    if !differs.is_empty() {
        return Err(RunError::Differs { path: path.to_path_buf(), differs });
    }
    check_growth(path, &saved, now)
}

/// Every setting of `a` and `b` but those in `skip` that differs, as `name (saved: A,
/// now: B)`, each value cut at 60 characters.
fn differences<C: RunSettings>(a: &C, b: &C, skip: &[&str]) -> Vec<String> {
    differing(a, b, skip)
        .into_iter()
        .map(|(name, x, y)| format!("{name} (saved: {}, now: {})", short(&x), short(&y)))
        .collect()
}

/// The `--episodes` rule of [`check`] (the other settings already agree).
fn check_growth<C: RunSettings>(path: &Path, saved: &C, now: &C) -> Result<(), RunError> {
    let (saved, now) = (saved.span(), now.span());
    let (was, now_n) = (saved.episodes, now.episodes);
    if was == now_n {
        return Ok(());
    }
    if now_n < was {
        return Err(RunError::Shrinks { path: path.to_path_buf(), was, now: now_n });
    }
    let batch = now.batch.max(1);
    if was % batch != 0 {
        let next = saved.seed_start + was as u64;
        return Err(RunError::PartBatch { was, now: now_n, batch, next });
    }
    if now.shard != (0, 1) {
        return Err(RunError::ShardGrows { path: path.to_path_buf(), now: now_n });
    }
    tracing::info!(from = was, to = now_n, "extending the run: only the new seeds are run");
    Ok(())
}

/// A setting's value for an error message, cut at 60 characters; `absent` for none.
fn short(text: &str) -> String {
    if text == "null" {
        return "absent".into();
    }
    if text.chars().count() > 60 {
        format!("{}…", text.chars().take(60).collect::<String>())
    } else {
        text.into()
    }
}

/// Puts a resumed or extended run's rows in the order a straight run appends them
/// (policy by policy in folder order, each policy's batches in seed order; rows within
/// a batch as the engine gave them), rewriting `episodes.jsonl` atomically when the
/// order changed. A run grown with `--episodes` appended its new batches after every
/// policy's old ones; sorted, its file equals the straight run's byte for byte.
///
/// # Errors
/// The file cannot be written.
pub fn straight_order(
    jsonl: &Path,
    rows: &mut [EpisodeRow],
    names: &[String],
    batches: &[&[u64]],
) -> Result<(), RunError> {
    let batch_of = |seed: u64| batches.iter().position(|b| b.contains(&seed)).unwrap_or(usize::MAX);
    let key =
        |r: &EpisodeRow| (names.iter().position(|n| *n == r.policy).unwrap_or(usize::MAX), batch_of(r.seed));
    if rows.windows(2).all(|w| key(&w[0]) <= key(&w[1])) {
        return Ok(());
    }
    rows.sort_by_key(key);
    let mut text = String::new();
    for r in rows.iter() {
        let line = serde_json::to_string(r)
            .map_err(|e| RunError::Io { path: jsonl.to_path_buf(), source: std::io::Error::other(e) })?;
        text.push_str(&line);
        text.push('\n');
    }
    harness::runfile::write_atomic(jsonl, &text).map_err(|e| RunError::Io {
        path: e.path,
        source: std::io::Error::other(format!("rewriting in run order: {}", e.message)),
    })
}

/// A `rank` row's (policy, seed, branch), for [`harness::rows::whole_batches`].
#[must_use]
pub fn rank_key(r: &EpisodeRow) -> (&str, u64, Branch) {
    (r.policy.as_str(), r.seed, r.branch)
}

/// The rows each seed of a whole `rank` batch has: one per branch.
pub const RANK_KINDS: [Branch; 2] = [Branch::Sim, Branch::WorldModel];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::tests::rank_config;
    use crate::config::{RankConfig, write};

    fn saved(dir: &Path, episodes: usize, shard: (usize, usize)) -> std::path::PathBuf {
        let path = dir.join("config.json");
        write(&path, &RankConfig { episodes, shard, ..rank_config() }).unwrap();
        path
    }

    fn now(episodes: usize, shard: (usize, usize)) -> RankConfig {
        RankConfig { command: "rank --resume".into(), episodes, shard, bootstrap: 100, ..rank_config() }
    }

    #[test]
    fn a_finished_run_of_whole_batches_grows() {
        let dir = tempfile::tempdir().unwrap();
        let path = saved(dir.path(), 100, (0, 1));
        check(&path, &now(100, (0, 1))).unwrap();
        check(&path, &now(250, (0, 1))).unwrap();
    }

    #[test]
    fn shrinking_a_part_batch_and_a_shard_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = saved(dir.path(), 100, (0, 1));
        let err = check(&path, &now(60, (0, 1))).unwrap_err().to_string();
        assert!(err.contains("--episodes 60 would drop"), "{err}");
        // 120 = 2 whole batches of 50 and a part batch of 20: seeds 100..220 would be
        // batched 100..150, 150..200, 200..250 by a straight run of 150.
        let path = saved(dir.path(), 120, (0, 1));
        let err = check(&path, &now(150, (0, 1))).unwrap_err().to_string();
        assert!(err.contains("part batch") && err.contains("--seed-start 220"), "{err}");
        let path = saved(dir.path(), 100, (1, 2));
        let err = check(&path, &now(200, (1, 2))).unwrap_err().to_string();
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
        let mut cfg = now(100, (0, 1));
        cfg.fingerprints.insert("policy p".into(), "sha256:bb".into());
        write(&path, &cfg).unwrap();
        check(&path, &cfg).unwrap();
        let mut other = cfg.clone();
        other.fingerprints.insert("policy p".into(), "sha256:cc".into());
        let err = check(&path, &other).unwrap_err().to_string();
        assert!(err.contains("content of policy p changed"), "{err}");
        // A file without fingerprints is not a rank configuration this version reads.
        let mut v = serde_json::to_value(&cfg).unwrap();
        v.as_object_mut().unwrap().remove("fingerprints");
        std::fs::write(&path, v.to_string()).unwrap();
        let err = check(&path, &cfg).unwrap_err().to_string();
        assert!(err.contains("missing field `fingerprints`") && err.contains("--force"), "{err}");
    }

    #[test]
    fn other_settings_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = saved(dir.path(), 100, (0, 1));
        let other = RankConfig { seed_start: 7, judge_every_frame: true, ..now(200, (0, 1)) };
        let err = check(&path, &other).unwrap_err().to_string();
        assert!(err.contains("seed_start (saved: 100, now: 7)") && !err.contains("episodes"), "{err}");
        assert!(err.contains("judge_every_frame (saved: false, now: true)"), "{err}");
    }

    #[test]
    fn a_config_written_before_the_types_resumes() {
        // The keys and value forms `rank` wrote with `json!` (sorted keys, the shard as
        // a list, the checkpoints as strings, an f32 α widened to f64 text).
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("config.json");
        let mut cfg = now(100, (0, 1));
        cfg.world_model_config.alpha = Some(0.3);
        let mut v = serde_json::to_value(&cfg).unwrap();
        // 0.30000001192092896: the f32 0.3 as json! wrote it.
        v["world_model_config"]["alpha"] = serde_json::json!(f64::from(0.3f32));
        v["shard"] = serde_json::json!([0, 1]);
        std::fs::write(&path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
        check(&path, &cfg).unwrap();
    }
}
