//! The rules `merge` joins `rank --shard i/n` folders by: exactly one complete split
//! of one run, every row of it present; and the configuration of the joined run.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use harness::results::{Branch, EpisodeRow, FailedPolicy};
use serde::Deserialize;

use crate::config::{RankConfig, differing};
use crate::error::RunError;
use crate::resume::RANK_KINDS;

/// Checks that `shards` (with their configurations `configs`) are exactly one
/// complete set: the same n, every i from 0 to n − 1 once, and the same run in every
/// other setting but the command line. A missing shard would leave policies with too
/// few episodes; a repeated one counts nothing twice but hides the missing one.
///
/// # Errors
/// [`RunError::Shards`]: counts that differ, an index missing, repeated or out of
/// range, or a setting that differs, naming the folders and the settings.
pub fn check_complete_set(shards: &[PathBuf], configs: &[RankConfig]) -> Result<(), RunError> {
    let (Some(first), Some(first_dir)) = (configs.first(), shards.first()) else {
        return Err(RunError::Shards("give at least one shard folder".into()));
    };
    let n = first.shard.1;
    let mut seen: Vec<Option<&PathBuf>> = vec![None; n];
    for (s, cfg) in shards.iter().zip(configs) {
        let (i, k) = cfg.shard;
        if k != n {
            return Err(RunError::Shards(format!(
                "{} is shard {i}/{k} but {} is one of {n}: not shards of one split",
                s.display(),
                first_dir.display()
            )));
        }
        let differs: Vec<&str> =
            differing(first, cfg, &["shard"]).into_iter().map(|(name, ..)| name).collect();
        if !differs.is_empty() {
            return Err(RunError::Shards(format!(
                "{}: not a shard of the same run as {} (they differ in {})",
                s.display(),
                first_dir.display(),
                differs.join(", ")
            )));
        }
        let Some(slot) = seen.get_mut(i) else {
            return Err(RunError::Shards(format!("{}: shard {i}/{n} is out of range", s.display())));
        };
        if let Some(other) = slot {
            return Err(RunError::Shards(format!(
                "{} and {} are both shard {i}/{n}; give each shard once",
                other.display(),
                s.display()
            )));
        }
        *slot = Some(s);
    }
    let missing: Vec<String> =
        seen.iter().enumerate().filter(|(_, s)| s.is_none()).map(|(i, _)| i.to_string()).collect();
    if !missing.is_empty() {
        return Err(RunError::Shards(format!(
            "shard {} of {n} missing: a merge needs all {n} shards of the run",
            missing.join(", ")
        )));
    }
    Ok(())
}

/// Refuses joined rows that lack a row of some (policy, seed, branch) of the run `cfg`:
/// a shard killed before it finished a batch, or a claim whose batch nobody ran, would
/// otherwise give a result over fewer episodes than the run says. Policies that failed
/// (reported in `failed`) are exempt.
///
/// # Errors
/// [`RunError::Shards`] for the first policy with missing rows, naming it and up to
/// five seeds.
pub fn check_every_row(
    rows: &[EpisodeRow],
    failed: &[FailedPolicy],
    cfg: &RankConfig,
) -> Result<(), RunError> {
    let seeds = harness::seed::range(cfg.seed_start, cfg.episodes as u64)
        .map_err(|e| RunError::Shards(format!("the shards' seeds: {e}")))?;
    let mut have: HashSet<(&str, u64, Branch)> = HashSet::with_capacity(rows.len());
    for r in rows {
        have.insert((r.policy.as_str(), r.seed, r.branch));
    }
    let n = cfg.episodes;
    for name in cfg.policy_names().iter().filter(|n| !failed.iter().any(|f| &f.policy == *n)) {
        let missing: Vec<u64> = seeds
            .clone()
            .filter(|&s| RANK_KINDS.iter().any(|&b| !have.contains(&(name.as_str(), s, b))))
            .collect();
        if !missing.is_empty() {
            let shown: Vec<String> = missing.iter().take(5).map(u64::to_string).collect();
            return Err(RunError::Shards(format!(
                "policy {name} lacks rows of {} of its {n} seeds ({}{}): a shard did not finish its \
                 batches; resume the shards (rank --shard i/n --resume, or rank --processes N --resume) \
                 and merge again",
                missing.len(),
                shown.join(", "),
                if missing.len() > 5 { ", ..." } else { "" }
            )));
        }
    }
    Ok(())
}

/// The configuration of the run joined from `shards`, whose first configuration is
/// `first`: a whole run (shard 0 of 1) that records where it came from.
#[must_use]
pub fn joined(first: &RankConfig, shards: &[PathBuf]) -> RankConfig {
    RankConfig { shard: (0, 1), merged_from: shards.to_vec(), ..first.clone() }
}

/// The number of shards the run whose first shard's configuration is `path` was split
/// into, when that file is there and says so (`rank --processes --resume` names the
/// count to resume with instead of refusing the settings).
#[must_use]
pub fn saved_split(path: &Path) -> Option<usize> {
    /// The one setting read: a partial view, so that a damaged or older file still
    /// says how it was split, and the full check comes later.
    #[derive(Deserialize)]
    struct Split {
        shard: (usize, usize),
    }
    let text = std::fs::read_to_string(path).ok()?;
    serde_json::from_str::<Split>(&text).ok().map(|s| s.shard.1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::tests::rank_config;

    fn shard(i: usize, n: usize) -> RankConfig {
        RankConfig { shard: (i, n), command: format!("rank --shard {i}/{n}"), ..rank_config() }
    }

    #[test]
    fn one_complete_split_is_accepted_and_anything_else_named() {
        let dirs: Vec<PathBuf> = ["s0", "s1", "s2"].iter().map(PathBuf::from).collect();
        check_complete_set(&dirs[..2], &[shard(1, 2), shard(0, 2)]).unwrap();
        let err = check_complete_set(&dirs[..2], &[shard(0, 2), shard(0, 2)]).unwrap_err().to_string();
        assert!(err.contains("s0 and s1 are both shard 0/2"), "{err}");
        let err = check_complete_set(&dirs[..2], &[shard(0, 3), shard(1, 3)]).unwrap_err().to_string();
        assert!(err.contains("shard 2 of 3 missing"), "{err}");
        let err = check_complete_set(&dirs[..2], &[shard(0, 2), shard(1, 3)]).unwrap_err().to_string();
        assert!(err.contains("s1 is shard 1/3 but s0 is one of 2"), "{err}");
        let other = RankConfig { seed: 3, max_steps: 9, ..shard(1, 2) };
        let err = check_complete_set(&dirs[..2], &[shard(0, 2), other]).unwrap_err().to_string();
        assert!(err.contains("they differ in max_steps, seed"), "{err}");
    }

    #[test]
    fn missing_rows_name_the_policy_and_seeds() {
        // 100 episodes from seed 100; epoch-0001 has both rows of every seed but 150's
        // world-model row; epoch-0002 failed and has none.
        let cfg = rank_config();
        let mut rows = Vec::new();
        for seed in 100..200 {
            for b in RANK_KINDS {
                if (seed, b) != (150, Branch::WorldModel) {
                    rows.push(EpisodeRow::new("epoch-0001", seed, b, 0.5, 0.5, 0.5, 0.95, 10));
                }
            }
        }
        let failed = [FailedPolicy { policy: "epoch-0002".into(), error: "x".into() }];
        let err = check_every_row(&rows, &failed, &cfg).unwrap_err().to_string();
        assert!(err.contains("policy epoch-0001 lacks rows of 1 of its 100 seeds (150)"), "{err}");
        rows.push(EpisodeRow::new("epoch-0001", 150, Branch::WorldModel, 0.5, 0.5, 0.5, 0.95, 10));
        check_every_row(&rows, &failed, &cfg).unwrap();
        let err = check_every_row(&rows, &[], &cfg).unwrap_err().to_string();
        assert!(err.contains("policy epoch-0002 lacks rows of 100 of its 100 seeds (100, 101"), "{err}");
    }

    #[test]
    fn the_split_is_read_from_a_partial_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("config.json");
        assert_eq!(saved_split(&path), None);
        std::fs::write(&path, r#"{"shard": [0, 3], "other": 1}"#).unwrap();
        assert_eq!(saved_split(&path), Some(3));
        let j = joined(&shard(1, 3), &[PathBuf::from("a")]);
        assert_eq!((j.shard, j.merged_from), ((0, 1), vec![PathBuf::from("a")]));
    }
}
