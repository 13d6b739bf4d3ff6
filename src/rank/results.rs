//! Episode rows and the statistics computed from them.
//!
//! `episodes.jsonl` is the source of truth: rows are appended as batches finish,
//! `--resume` reads them back to skip finished episodes, `merge` concatenates
//! shards' rows, and `results.json` is always recomputed from the (sorted) rows,
//! so a resumed, sharded or multi-threaded run gives the same results as one
//! uninterrupted run.

use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::path::Path;

use anyhow::{Context, Result};
use harness::metrics::agreement;
use harness::metrics::bootstrap::{agreement_ci, mean_ci, wilson};
use harness::results::{AgreementSummary, BranchStats, PolicyResult};
use serde::Serialize;

pub use harness::results::{Branch, EpisodeRow};

/// Reads `episodes.jsonl` (missing file: no rows).
///
/// # Errors
/// An unreadable file or a malformed line, naming the file and line.
pub fn read_rows<T: serde::de::DeserializeOwned>(path: &Path) -> Result<Vec<T>> {
    if !path.exists() {
        return Ok(Vec::new());
    }
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str(l).with_context(|| format!("{} line {}: invalid row", path.display(), i + 1))
        })
        .collect()
}

/// Reads `episodes.jsonl` to continue a run (`rank --resume`, `plan --resume`) at the
/// granularity it can reproduce bit for bit: whole batches.
///
/// - A last line cut mid-way (a run killed while writing) is dropped, with a warning;
///   a malformed line before the last is an error naming it.
/// - `keep` marks the rows to keep: those of batches that are whole (every seed with
///   all its rows, none twice). The others are dropped, with a warning, and their
///   batches run again whole, since a batch of another shape rounds differently.
/// - When anything changed (rows dropped, a missing final newline), the file is
///   rewritten with the kept rows, atomically (a temporary file renamed over it).
///
/// # Errors
/// An unreadable or unwritable file, or a malformed line before the last.
pub fn resume_rows<T: Serialize + serde::de::DeserializeOwned>(
    path: &Path,
    keep: impl Fn(&[T]) -> Vec<bool>,
) -> Result<Vec<T>> {
    if !path.exists() {
        return Ok(Vec::new());
    }
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let lines: Vec<(usize, &str)> = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()).collect();
    let mut rows = Vec::with_capacity(lines.len());
    for (k, (i, line)) in lines.iter().enumerate() {
        match serde_json::from_str::<T>(line) {
            Ok(r) => rows.push(r),
            Err(e) if k + 1 == lines.len() => {
                tracing::warn!("{} line {}: a torn last row ({e}); dropped", path.display(), i + 1);
            }
            Err(e) => {
                return Err(e).with_context(|| format!("{} line {}: invalid row", path.display(), i + 1));
            }
        }
    }
    let mask = keep(&rows);
    let before = rows.len();
    let rows: Vec<T> = rows.into_iter().zip(mask).filter_map(|(r, k)| k.then_some(r)).collect();
    if rows.len() < before {
        tracing::warn!(
            "{}: dropped {} rows of incomplete batches; those batches run again whole",
            path.display(),
            before - rows.len()
        );
    }
    let mut kept = String::new();
    for r in &rows {
        kept.push_str(&serde_json::to_string(r)?);
        kept.push('\n');
    }
    if kept != text {
        let tmp = path.with_extension("jsonl.tmp");
        std::fs::write(&tmp, &kept)
            .and_then(|()| std::fs::File::open(&tmp)?.sync_all())
            .and_then(|()| std::fs::rename(&tmp, path))
            .with_context(|| format!("rewriting {}", path.display()))?;
    }
    Ok(rows)
}

/// Marks the rows of whole batches, for [`resume_rows`]: a row is kept when its seed's
/// batch (of this run's `batches`) holds, for the row's group (its policy, or its
/// planner), exactly one row of each of `kinds` per seed (`rank`: a MuJoCo and a
/// world-model row; `plan`: one row). Rows of partial or doubled batches, and of
/// seeds outside the run, are not. `key` gives a row's (group, seed, kind).
pub fn whole_batches<T, K: Copy + Eq + std::hash::Hash>(
    rows: &[T],
    batches: &[&[u64]],
    key: impl for<'a> Fn(&'a T) -> (&'a str, u64, K),
    kinds: &[K],
) -> Vec<bool> {
    let mut count: HashMap<(&str, u64, K), usize> = HashMap::new();
    for r in rows {
        *count.entry(key(r)).or_default() += 1;
    }
    let batch_of: HashMap<u64, usize> =
        batches.iter().enumerate().flat_map(|(b, seeds)| seeds.iter().map(move |&s| (s, b))).collect();
    let whole = |group: &str, b: usize| {
        batches[b].iter().all(|&s| kinds.iter().all(|&k| count.get(&(group, s, k)) == Some(&1)))
    };
    rows.iter()
        .map(|r| {
            let (group, seed, _) = key(r);
            batch_of.get(&seed).is_some_and(|&b| whole(group, b))
        })
        .collect()
}

/// Appends rows (of `rank` or `plan`) to an `episodes.jsonl`, synced, so a killed run keeps its finished batches.
///
/// # Errors
/// I/O failures naming the file.
pub fn append_rows<T: Serialize>(path: &Path, rows: &[T]) -> Result<()> {
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .with_context(|| format!("opening {}", path.display()))?;
    let mut text = String::new();
    for r in rows {
        text.push_str(&serde_json::to_string(r)?);
        text.push('\n');
    }
    f.write_all(text.as_bytes())
        .and_then(|()| f.sync_data())
        .with_context(|| format!("writing {}", path.display()))
}

/// Mean, bootstrap CI, success rate and Wilson CI of one branch of one policy.
pub fn branch_stats(rows: &[&EpisodeRow], bootstrap: usize, seed: u64) -> BranchStats {
    let scores: Vec<f64> = rows.iter().map(|r| r.score).collect();
    let n = scores.len();
    let k = rows.iter().filter(|r| r.success).count();
    let mean_of = |v: Vec<f64>| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
    let (lo, hi) = wilson(k, n, 1.959_963_984_540_054);
    BranchStats {
        mean: scores.iter().sum::<f64>() / n.max(1) as f64,
        ci95: mean_ci(&scores, bootstrap, seed),
        success_rate: k as f64 / n.max(1) as f64,
        success_ci95: [lo, hi],
        episodes: n,
        block_area: mean_of(rows.iter().filter_map(|r| r.block_area).collect()),
        goal_kept: mean_of(rows.iter().filter_map(|r| r.goal_kept).collect()),
        agent_kept: mean_of(rows.iter().filter_map(|r| r.agent_kept).collect()),
    }
}

/// Per-policy statistics and agreement, from rows (any order; sorted here).
/// `policies` fixes the output order; policies without complete pairs are skipped.
pub fn summarise(
    rows: &[EpisodeRow],
    policies: &[String],
    bootstrap: usize,
    seed: u64,
) -> (Vec<PolicyResult>, AgreementSummary) {
    let mut by: BTreeMap<(&str, u64), [Option<&EpisodeRow>; 2]> = BTreeMap::new();
    for r in rows {
        let e = by.entry((r.policy.as_str(), r.seed)).or_default();
        e[usize::from(r.branch == Branch::WorldModel)] = Some(r);
    }
    let mut out = Vec::new();
    let mut pairs: Vec<(Vec<f64>, Vec<f64>)> = Vec::new();
    let mut names = Vec::new();
    for p in policies {
        let eps: Vec<[&EpisodeRow; 2]> = by
            .range((p.as_str(), 0)..=(p.as_str(), u64::MAX))
            .filter_map(|(_, v)| Some([v[0]?, v[1]?]))
            .collect();
        if eps.is_empty() {
            continue;
        }
        let sim: Vec<&EpisodeRow> = eps.iter().map(|e| e[0]).collect();
        let wm: Vec<&EpisodeRow> = eps.iter().map(|e| e[1]).collect();
        let errs: Vec<f64> = sim.iter().filter_map(|r| r.scorer_abs_error).collect();
        out.push(PolicyResult {
            name: p.clone(),
            sim: branch_stats(&sim, bootstrap, seed),
            world_model: branch_stats(&wm, bootstrap, seed),
            frame_scorer_mean_abs_error: errs.iter().sum::<f64>() / errs.len().max(1) as f64,
        });
        pairs.push((wm.iter().map(|r| r.score).collect(), sim.iter().map(|r| r.score).collect()));
        names.push(p.as_str());
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let pred: Vec<f64> = pairs.iter().map(|(w, _)| mean(w)).collect();
    let act: Vec<f64> = pairs.iter().map(|(_, s)| mean(s)).collect();
    let m = agreement(&pred, &act);
    let ci = (pairs.len() >= 2 && pairs.iter().all(|(w, _)| w.len() >= 2))
        .then(|| agreement_ci(&pairs, bootstrap, seed));
    (out, m.summary(&names, ci.as_ref()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(p: &str, seed: u64, b: Branch, score: f64) -> EpisodeRow {
        EpisodeRow::new(p, seed, b, score, score * 0.95, 0.0, 0.95, 10)
    }

    #[test]
    fn summary_pairs_branches_and_computes_agreement() {
        // Policy a: sim (0.2, 0.4) mean 0.3, wm (0.1, 0.3) mean 0.2;
        // policy b: sim (0.8, 1.0) mean 0.9, wm (0.7, 0.9) mean 0.8. Same order: r = 1, no inversion.
        let rows = vec![
            row("b", 2, Branch::WorldModel, 0.9),
            row("a", 1, Branch::Sim, 0.2),
            row("a", 1, Branch::WorldModel, 0.1),
            row("a", 2, Branch::Sim, 0.4),
            row("a", 2, Branch::WorldModel, 0.3),
            row("b", 1, Branch::Sim, 0.8),
            row("b", 1, Branch::WorldModel, 0.7),
            row("b", 2, Branch::Sim, 1.0),
            row("a", 3, Branch::Sim, 0.9), // unpaired: ignored
        ];
        let s = summarise(&rows, &["a".into(), "b".into()], 200, 0);
        assert!((s.0[0].sim.mean - 0.3).abs() < 1e-12);
        assert!((s.0[1].world_model.mean - 0.8).abs() < 1e-12);
        // Success: max coverage = 0.95 score > 0.95 only for score 1.0 (0.95 > 0.95 is false): none.
        assert_eq!(s.0[1].sim.success_rate, 0.0);
        assert!((s.1.pearson.unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(s.1.rank_inversions, Some(0));
        // No scene checks recorded (as in runs made before they existed): null.
        assert_eq!(s.0[0].sim.block_area, None);
        // Same input in another order gives the same summary.
        let mut rev = rows.clone();
        rev.reverse();
        assert_eq!(summarise(&rev, &["a".into(), "b".into()], 200, 0), s);
    }
}
