//! `episodes.jsonl`: the rows of a ranking or planning run, one JSON object a line.
//!
//! The file is the run's source of truth: rows are appended (synced) as batches
//! finish, `--resume` reads them back at the granularity a run can reproduce bit
//! for bit (whole batches), and `merge` concatenates shards' rows. Generic over the
//! row type (`rank`'s [`EpisodeRow`](crate::results::EpisodeRow), `plan`'s rows).

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;

/// Why rows could not be read or written, naming the file (and line).
#[derive(Debug, thiserror::Error)]
pub enum RowsError {
    /// The file could not be read.
    #[error("reading {}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file could not be written.
    #[error("writing {}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A malformed line.
    #[error("{} line {line}: invalid row", path.display())]
    Row {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// The parser's error.
        source: serde_json::Error,
    },
    /// A row that does not serialise.
    #[error("a row that does not serialise")]
    Serialize(#[source] serde_json::Error),
}

fn to_line<T: Serialize>(r: &T) -> Result<String, RowsError> {
    serde_json::to_string(r).map_err(RowsError::Serialize)
}

/// Reads `episodes.jsonl` (missing file: no rows).
///
/// # Errors
/// An unreadable file or a malformed line, naming the file and line.
pub fn read_rows<T: serde::de::DeserializeOwned>(path: &Path) -> Result<Vec<T>, RowsError> {
    if !path.exists() {
        return Ok(Vec::new());
    }
    let text =
        std::fs::read_to_string(path).map_err(|source| RowsError::Read { path: path.into(), source })?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str(l).map_err(|source| RowsError::Row {
                path: path.into(),
                line: i + 1,
                source,
            })
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
) -> Result<Vec<T>, RowsError> {
    if !path.exists() {
        return Ok(Vec::new());
    }
    let text =
        std::fs::read_to_string(path).map_err(|source| RowsError::Read { path: path.into(), source })?;
    let lines: Vec<(usize, &str)> = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()).collect();
    let mut rows = Vec::with_capacity(lines.len());
    for (k, (i, line)) in lines.iter().enumerate() {
        match serde_json::from_str::<T>(line) {
            Ok(r) => rows.push(r),
            Err(e) if k + 1 == lines.len() => {
                tracing::warn!("{} line {}: a torn last row ({e}); dropped", path.display(), i + 1);
            }
            Err(e) => {
                return Err(RowsError::Row { path: path.into(), line: i + 1, source: e });
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
        kept.push_str(&to_line(r)?);
        kept.push('\n');
    }
    if kept != text {
        let tmp = path.with_extension("jsonl.tmp");
        std::fs::write(&tmp, &kept)
            .and_then(|()| std::fs::File::open(&tmp)?.sync_all())
            .and_then(|()| std::fs::rename(&tmp, path))
            .map_err(|source| RowsError::Write { path: path.into(), source })?;
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
pub fn append_rows<T: Serialize>(path: &Path, rows: &[T]) -> Result<(), RowsError> {
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(|source| RowsError::Write { path: path.into(), source })?;
    let mut text = String::new();
    for r in rows {
        text.push_str(&to_line(r)?);
        text.push('\n');
    }
    f.write_all(text.as_bytes())
        .and_then(|()| f.sync_data())
        .map_err(|source| RowsError::Write { path: path.into(), source })
}
