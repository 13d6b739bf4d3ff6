//! `episodes.parquet`: a `rank` run's per-episode table as one columnar file.
//!
//! `episodes.jsonl` is the run's source of truth (appended as batches finish,
//! read back by `--resume`); this is the same rows, sorted by (policy, seed,
//! branch), typed and compressed, for analysis with polars, pandas, pyarrow or DuckDB
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
//! Written with the parquet crate's column writers (snappy pages, fixed options, no
//! timestamps), so the same rows give the same bytes.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use harness::results::EpisodeRow;
use parquet::basic::Compression;
use parquet::data_type::{BoolType, ByteArray, ByteArrayType, DoubleType, Int32Type, Int64Type};
use parquet::file::properties::WriterProperties;
use parquet::file::reader::{FileReader, SerializedFileReader};
use parquet::file::writer::SerializedFileWriter;
use parquet::record::{Field, Row};
use parquet::schema::parser::parse_message_type;

/// A problem writing or reading the table, naming the file.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct TableError {
    /// The file.
    pub path: PathBuf,
    /// What went wrong.
    pub message: String,
}

/// The table's schema, in the column order of the module's table.
const SCHEMA: &str = "message episodes {
    REQUIRED BYTE_ARRAY policy (STRING);
    REQUIRED INT64 seed (INTEGER(64, false));
    REQUIRED BYTE_ARRAY branch (STRING);
    REQUIRED DOUBLE score;
    REQUIRED DOUBLE max_coverage;
    REQUIRED DOUBLE final_coverage;
    REQUIRED BOOLEAN success;
    REQUIRED INT32 steps (INTEGER(32, false));
    OPTIONAL DOUBLE final_block_x;
    OPTIONAL DOUBLE final_block_y;
    OPTIONAL DOUBLE final_block_theta;
    REQUIRED DOUBLE goal_x;
    REQUIRED DOUBLE goal_y;
    REQUIRED DOUBLE goal_theta;
    OPTIONAL DOUBLE scorer_abs_error;
    OPTIONAL DOUBLE block_area;
    OPTIONAL DOUBLE goal_kept;
    OPTIONAL DOUBLE agent_kept;
}";

/// Columns of [`SCHEMA`].
pub const COLUMNS: usize = 18;

/// One column's values: the present ones, and for an optional column its definition
/// levels (1 present, 0 null).
enum Values {
    Str(Vec<ByteArray>),
    U64(Vec<i64>),
    U32(Vec<i32>),
    Bool(Vec<bool>),
    F64(Vec<f64>),
    Opt(Vec<f64>, Vec<i16>),
}

fn optional(v: impl Iterator<Item = Option<f64>>) -> Values {
    let v: Vec<Option<f64>> = v.collect();
    Values::Opt(v.iter().flatten().copied().collect(), v.iter().map(|x| i16::from(x.is_some())).collect())
}

/// The columns of `rows`, in [`SCHEMA`]'s order.
fn columns(rows: &[&EpisodeRow]) -> Vec<Values> {
    let f = |g: fn(&EpisodeRow) -> f64| Values::F64(rows.iter().map(|r| g(r)).collect());
    let block = |k: usize| optional(rows.iter().map(|r| r.final_block.map(|b| b[k])));
    let goal = |k: usize| Values::F64(rows.iter().map(|r| r.goal[k]).collect());
    let text = |g: fn(&EpisodeRow) -> &str| Values::Str(rows.iter().map(|r| ByteArray::from(g(r))).collect());
    vec![
        text(|r| r.policy.as_str()),
        // The parquet type is INT64 annotated unsigned: the bits of the u64.
        Values::U64(rows.iter().map(|r| r.seed as i64).collect()),
        text(|r| r.branch.as_str()),
        f(|r| r.score),
        f(|r| r.max_coverage),
        f(|r| r.final_coverage),
        Values::Bool(rows.iter().map(|r| r.success).collect()),
        Values::U32(rows.iter().map(|r| r.steps as i32).collect()),
        block(0),
        block(1),
        block(2),
        goal(0),
        goal(1),
        goal(2),
        optional(rows.iter().map(|r| r.scorer_abs_error)),
        optional(rows.iter().map(|r| r.block_area)),
        optional(rows.iter().map(|r| r.goal_kept)),
        optional(rows.iter().map(|r| r.agent_kept)),
    ]
}

/// Writes `rows` to `path` (one row group, snappy-compressed pages).
///
/// # Errors
/// [`TableError`] naming `path` if it cannot be created or written.
pub fn write_episodes_parquet(path: &Path, rows: &[&EpisodeRow]) -> Result<(), TableError> {
    let err = |m: String| TableError { path: path.to_path_buf(), message: m };
    let schema = Arc::new(parse_message_type(SCHEMA).map_err(|e| err(e.to_string()))?);
    let props = Arc::new(
        WriterProperties::builder()
            .set_compression(Compression::SNAPPY)
            .set_created_by("evalharness".into())
            .build(),
    );
    let file = std::fs::File::create(path).map_err(|e| err(e.to_string()))?;
    let mut writer = SerializedFileWriter::new(file, schema, props).map_err(|e| err(e.to_string()))?;
    let mut group = writer.next_row_group().map_err(|e| err(e.to_string()))?;
    for values in columns(rows) {
        let Some(mut col) = group.next_column().map_err(|e| err(e.to_string()))? else {
            return Err(err("fewer columns in the schema than in the table".into()));
        };
        let written = match &values {
            Values::Str(v) => col.typed::<ByteArrayType>().write_batch(v, None, None),
            Values::U64(v) => col.typed::<Int64Type>().write_batch(v, None, None),
            Values::U32(v) => col.typed::<Int32Type>().write_batch(v, None, None),
            Values::Bool(v) => col.typed::<BoolType>().write_batch(v, None, None),
            Values::F64(v) => col.typed::<DoubleType>().write_batch(v, None, None),
            Values::Opt(v, def) => col.typed::<DoubleType>().write_batch(v, Some(def), None),
        };
        written.map_err(|e| err(e.to_string()))?;
        col.close().map_err(|e| err(e.to_string()))?;
    }
    group.close().map_err(|e| err(e.to_string()))?;
    writer.close().map_err(|e| err(e.to_string()))?;
    Ok(())
}

/// Reads a table written by [`write_episodes_parquet`]: its rows, each with its named fields.
///
/// # Errors
/// [`TableError`] naming `path` if it is missing or not parquet.
pub fn read_episodes_parquet(path: &Path) -> Result<Vec<Row>, TableError> {
    let err = |m: String| TableError { path: path.to_path_buf(), message: m };
    let file = std::fs::File::open(path).map_err(|e| err(e.to_string()))?;
    let reader = SerializedFileReader::new(file).map_err(|e| err(e.to_string()))?;
    let rows = reader.get_row_iter(None).map_err(|e| err(e.to_string()))?;
    rows.map(|r| r.map_err(|e| err(e.to_string()))).collect()
}

/// The field `name` of a row read by [`read_episodes_parquet`].
pub fn field<'a>(row: &'a Row, name: &str) -> Option<&'a Field> {
    row.get_column_iter().find(|(n, _)| n.as_str() == name).map(|(_, f)| f)
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
        let t = read_episodes_parquet(&path).unwrap();
        assert_eq!(t.len(), 2);
        assert_eq!(t[0].len(), COLUMNS);
        let get = |r: usize, name: &str| field(&t[r], name).cloned();
        // Unsigned 64-bit seeds come back as such.
        assert_eq!(get(1, "seed"), Some(Field::ULong(100_000)));
        assert_eq!(get(0, "steps"), Some(Field::UInt(300)));
        assert_eq!(
            (get(0, "final_block_x"), get(1, "final_block_x")),
            (Some(Field::Double(250.0)), Some(Field::Null))
        );
        assert_eq!(
            (get(0, "block_area"), get(1, "block_area")),
            (Some(Field::Double(0.98)), Some(Field::Null))
        );
        assert_eq!(
            (get(0, "agent_kept"), get(1, "agent_kept")),
            (Some(Field::Double(0.99)), Some(Field::Double(0.02)))
        );
        assert_eq!(get(1, "branch"), Some(Field::Str("world_model".into())));
        assert_eq!(get(0, "success"), Some(Field::Bool(false)));
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
