//! `episodes.parquet`: a `rank` run's per-episode table as one columnar file.
//!
//! `episodes.jsonl` is the run's source of truth (appended as batches finish,
//! read back by `--resume`); this is the same rows, sorted by (policy, seed,
//! branch), typed and compressed, for analysis with polars, pandas or DuckDB
//! without parsing JSON. Columns:
//!
//! | column | type | meaning |
//! |---|---|---|
//! | `policy` | str | checkpoint folder name |
//! | `seed` | u64 | episode seed |
//! | `branch` | str | `sim` (MuJoCo) or `world_model` |
//! | `score` | f64 | max over the episode of clip(coverage / threshold, 0, 1) |
//! | `max_coverage`, `final_coverage` | f64 | coverage of the goal |
//! | `success` | bool | coverage ever above the threshold |
//! | `steps` | u32 | control steps executed |
//! | `final_block_x`, `_y`, `_theta` | f64, null in the world-model branch | final block pose |
//! | `goal_x`, `goal_y`, `goal_theta` | f64 | goal pose |
//! | `scorer_abs_error` | f64, null in the world-model branch | frame scorer's mean error on real frames |
//! | `block_area` | f64, null in runs written before it existed | block pixels in the last frame the policy saw, as a fraction of the T's area (≈ 1.06 in MuJoCo; how much of the block a world-model rollout kept) |
//! | `goal_kept` | f64, null in runs written before it existed | fraction of the (static) goal T that frame still shows (≈ 0.94–0.99 in MuJoCo) |
//! | `agent_kept` | f64, null in runs written before it existed | agent pixels in that frame as a fraction of the agent disk's area, capped at 1 (≈ 1 in MuJoCo; near 0 when a world-model rollout lost the agent) |
//!
//! Written single-threaded with fixed options, so the same rows give the same bytes.

use std::path::{Path, PathBuf};

use harness::results::EpisodeRow;
use polars::prelude::*;

/// A problem writing or reading the table, naming the file.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct TableError {
    /// The file.
    pub path: PathBuf,
    /// What went wrong.
    pub message: String,
}

/// The rows as a data frame (in the given order).
///
/// # Errors
/// A polars error if the columns cannot be assembled (not expected for any rows).
pub fn episodes_frame(rows: &[&EpisodeRow]) -> PolarsResult<DataFrame> {
    let f = |g: fn(&EpisodeRow) -> f64| rows.iter().map(|r| g(r)).collect::<Vec<f64>>();
    let block = |k: usize| rows.iter().map(|r| r.final_block.map(|b| b[k])).collect::<Vec<Option<f64>>>();
    let goal = |k: usize| rows.iter().map(|r| r.goal[k]).collect::<Vec<f64>>();
    DataFrame::new(
        rows.len(),
        vec![
            Column::new("policy".into(), rows.iter().map(|r| r.policy.as_str()).collect::<Vec<_>>()),
            Column::new("seed".into(), rows.iter().map(|r| r.seed).collect::<Vec<u64>>()),
            Column::new("branch".into(), rows.iter().map(|r| r.branch.as_str()).collect::<Vec<_>>()),
            Column::new("score".into(), f(|r| r.score)),
            Column::new("max_coverage".into(), f(|r| r.max_coverage)),
            Column::new("final_coverage".into(), f(|r| r.final_coverage)),
            Column::new("success".into(), rows.iter().map(|r| r.success).collect::<Vec<bool>>()),
            Column::new("steps".into(), rows.iter().map(|r| r.steps as u32).collect::<Vec<u32>>()),
            Column::new("final_block_x".into(), block(0)),
            Column::new("final_block_y".into(), block(1)),
            Column::new("final_block_theta".into(), block(2)),
            Column::new("goal_x".into(), goal(0)),
            Column::new("goal_y".into(), goal(1)),
            Column::new("goal_theta".into(), goal(2)),
            Column::new(
                "scorer_abs_error".into(),
                rows.iter().map(|r| r.scorer_abs_error).collect::<Vec<_>>(),
            ),
            Column::new("block_area".into(), rows.iter().map(|r| r.block_area).collect::<Vec<_>>()),
            Column::new("goal_kept".into(), rows.iter().map(|r| r.goal_kept).collect::<Vec<_>>()),
            Column::new("agent_kept".into(), rows.iter().map(|r| r.agent_kept).collect::<Vec<_>>()),
        ],
    )
}

/// Writes `rows` to `path` (zstd-compressed parquet).
///
/// # Errors
/// [`TableError`] naming `path` if it cannot be created or written.
pub fn write_episodes_parquet(path: &Path, rows: &[&EpisodeRow]) -> Result<(), TableError> {
    let err = |m: String| TableError { path: path.to_path_buf(), message: m };
    let mut df = episodes_frame(rows).map_err(|e| err(e.to_string()))?;
    let file = std::fs::File::create(path).map_err(|e| err(e.to_string()))?;
    ParquetWriter::new(file).set_parallel(false).finish(&mut df).map_err(|e| err(e.to_string()))?;
    Ok(())
}

/// Reads a table written by [`write_episodes_parquet`].
///
/// # Errors
/// [`TableError`] naming `path` if it is missing or not parquet.
pub fn read_episodes_parquet(path: &Path) -> Result<DataFrame, TableError> {
    let err = |m: String| TableError { path: path.to_path_buf(), message: m };
    let file = std::fs::File::open(path).map_err(|e| err(e.to_string()))?;
    ParquetReader::new(file).finish().map_err(|e| err(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use harness::judge::SceneCheck;
    use harness::results::Branch;

    fn rows() -> Vec<EpisodeRow> {
        let r = EpisodeRow::new("epoch-0002", 100_000, Branch::Sim, 0.5, 0.475, 0.4, 0.95, 300)
            .with_poses(Some([250.0, 260.0, 0.5]), [256.0, 256.0, 0.785])
            .with_scorer_error(Some(0.01))
            .with_scene(Some(SceneCheck { block_area: 0.98, goal_kept: 0.95, agent_kept: 0.99 }));
        let mut w =
            EpisodeRow { branch: Branch::WorldModel, final_block: None, scorer_abs_error: None, ..r.clone() };
        w = w.with_scene(None);
        w.agent_kept = Some(0.02);
        vec![r, w]
    }

    #[test]
    fn round_trips_with_types_and_nulls() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("episodes.parquet");
        write_episodes_parquet(&path, &rows().iter().collect::<Vec<_>>()).unwrap();
        let df = read_episodes_parquet(&path).unwrap();
        assert_eq!(df.height(), 2);
        assert_eq!(df.width(), 18);
        let seed = df.column("seed").unwrap();
        assert_eq!(seed.dtype(), &DataType::UInt64);
        assert_eq!(seed.u64().unwrap().get(1), Some(100_000));
        let x = df.column("final_block_x").unwrap().f64().unwrap();
        assert_eq!((x.get(0), x.get(1)), (Some(250.0), None));
        let area = df.column("block_area").unwrap().f64().unwrap();
        assert_eq!((area.get(0), area.get(1)), (Some(0.98), None));
        let agent = df.column("agent_kept").unwrap().f64().unwrap();
        assert_eq!((agent.get(0), agent.get(1)), (Some(0.99), Some(0.02)));
        assert_eq!(df.column("branch").unwrap().str().unwrap().get(1), Some("world_model"));
        assert_eq!(df.column("success").unwrap().bool().unwrap().get(0), Some(false));
        // Same rows, same bytes.
        let again = dir.path().join("again.parquet");
        write_episodes_parquet(&again, &rows().iter().collect::<Vec<_>>()).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), std::fs::read(&again).unwrap());
    }

    #[test]
    fn a_missing_or_corrupt_file_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("episodes.parquet");
        let e = read_episodes_parquet(&path).unwrap_err();
        assert!(e.to_string().contains("episodes.parquet"), "{e}");
        std::fs::write(&path, b"not parquet").unwrap();
        assert!(read_episodes_parquet(&path).is_err());
    }
}
