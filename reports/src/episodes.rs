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
//! | `score` | f64 | max over the episode of the task's reward (its raw score mapped to [0, 1]) |
//! | `max_raw`, `final_raw` | f64 | the raw score's maximum and last value (Push-T: goal coverage; Lift, Can: success) |
//! | `success` | bool | the raw score ever above the task's threshold |
//! | `steps` | u32 | control steps executed |
//! | `scorer_abs_error` | f64, null in the world-model branch | the judge's mean error on real frames |
//! | the task's named state, in name order | f64, null where a row lacks it | [`EpisodeRow::state`]; Push-T: `final_block_theta`, `final_block_x`, `final_block_y` (null in the world-model branch), `goal_theta`, `goal_x`, `goal_y`; Lift, Can: `final_object_x`, `_y`, `_yaw` |
//! | the judge's scene checks, in name order | f64, null where a row lacks it | [`EpisodeRow::scene`]; Push-T: `agent_kept`, `block_area`, `goal_kept` (about 1 in MuJoCo; how much of the scene a world-model rollout kept) |
//!
//! The task's columns are those its rows name, so each task's table has its own. A name
//! that is not a plain identifier (letters, digits, `_`) or that repeats a column is refused.
//!
//! [`EpisodeRow::state`]: harness::results::EpisodeRow::state
//! [`EpisodeRow::scene`]: harness::results::EpisodeRow::scene
//!
//! Written with the parquet crate's column writers (snappy pages, fixed options, no
//! timestamps), so the same rows give the same bytes.

use std::collections::BTreeSet;
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

/// The columns every task has, in the module's table's order.
const FIXED: &str = "
    REQUIRED BYTE_ARRAY policy (STRING);
    REQUIRED INT64 seed (INTEGER(64, false));
    REQUIRED BYTE_ARRAY branch (STRING);
    REQUIRED DOUBLE score;
    REQUIRED DOUBLE max_raw;
    REQUIRED DOUBLE final_raw;
    REQUIRED BOOLEAN success;
    REQUIRED INT32 steps (INTEGER(32, false));
    OPTIONAL DOUBLE scorer_abs_error;";

/// Columns every table has ([`FIXED`]).
pub const FIXED_COLUMNS: usize = 9;

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

/// The task's named columns of `rows`: every state name, then every scene-check name, each
/// in name order; `Err` names one that is not an identifier or repeats a column.
fn named_columns(rows: &[&EpisodeRow]) -> Result<(Vec<String>, Vec<String>), String> {
    let state: BTreeSet<&String> = rows.iter().flat_map(|r| r.state.keys()).collect();
    let scene: BTreeSet<&String> = rows.iter().flat_map(|r| r.scene.keys()).collect();
    let fixed =
        ["policy", "seed", "branch", "score", "max_raw", "final_raw", "success", "steps", "scorer_abs_error"];
    let mut seen: BTreeSet<&str> = fixed.into_iter().collect();
    for name in state.iter().chain(&scene) {
        let ident = name.chars().next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
            && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
        if !ident {
            return Err(format!(
                "a task's column name {name:?} is not a plain identifier (letters, digits, _)"
            ));
        }
        if !seen.insert(name.as_str()) {
            return Err(format!(
                "the column name {name:?} appears twice (a task's state or scene check repeats it)"
            ));
        }
    }
    Ok((state.into_iter().cloned().collect(), scene.into_iter().cloned().collect()))
}

/// The schema for the named columns after [`FIXED`].
fn schema(state: &[String], scene: &[String]) -> String {
    let named: String = state.iter().chain(scene).map(|n| format!("\n    OPTIONAL DOUBLE {n};")).collect();
    format!("message episodes {{{FIXED}{named}\n}}")
}

/// The columns of `rows`, in [`schema`]'s order.
fn columns(rows: &[&EpisodeRow], state: &[String], scene: &[String]) -> Vec<Values> {
    let f = |g: fn(&EpisodeRow) -> f64| Values::F64(rows.iter().map(|r| g(r)).collect());
    let text = |g: fn(&EpisodeRow) -> &str| Values::Str(rows.iter().map(|r| ByteArray::from(g(r))).collect());
    let mut out = vec![
        text(|r| r.policy.as_str()),
        // The parquet type is INT64 annotated unsigned: the bits of the u64.
        Values::U64(rows.iter().map(|r| r.seed as i64).collect()),
        text(|r| r.branch.as_str()),
        f(|r| r.score),
        f(|r| r.max_raw),
        f(|r| r.final_raw),
        Values::Bool(rows.iter().map(|r| r.success).collect()),
        Values::U32(rows.iter().map(|r| r.steps as i32).collect()),
        optional(rows.iter().map(|r| r.scorer_abs_error)),
    ];
    out.extend(state.iter().map(|n| optional(rows.iter().map(|r| r.state.get(n).copied()))));
    out.extend(scene.iter().map(|n| optional(rows.iter().map(|r| r.scene.get(n).copied()))));
    out
}

/// Writes `rows` to `path` (one row group, snappy-compressed pages).
///
/// # Errors
/// [`TableError`] naming `path` if it cannot be created or written.
pub fn write_episodes_parquet(path: &Path, rows: &[&EpisodeRow]) -> Result<(), TableError> {
    let err = |m: String| TableError { path: path.to_path_buf(), message: m };
    let (state, scene) = named_columns(rows).map_err(err)?;
    let schema = Arc::new(parse_message_type(&schema(&state, &scene)).map_err(|e| err(e.to_string()))?);
    let props = Arc::new(
        WriterProperties::builder()
            .set_compression(Compression::SNAPPY)
            .set_created_by("evalharness".into())
            .build(),
    );
    let file = std::fs::File::create(path).map_err(|e| err(e.to_string()))?;
    let mut writer = SerializedFileWriter::new(file, schema, props).map_err(|e| err(e.to_string()))?;
    let mut group = writer.next_row_group().map_err(|e| err(e.to_string()))?;
    for values in columns(rows, &state, &scene) {
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
        let goal = [("goal_x", 256.0), ("goal_y", 256.0), ("goal_theta", 0.785)];
        let r = EpisodeRow::new("epoch-0002", 100_000, Branch::Sim, 0.5, 0.475, 0.4, 0.95, 300)
            .with_state(&goal)
            .with_state(&[("final_block_x", 250.0), ("final_block_y", 260.0), ("final_block_theta", 0.5)])
            .with_scorer_error(Some(0.01))
            .with_scene(Some(&SceneCheck(vec![
                ("block_area", 0.98),
                ("goal_kept", 0.95),
                ("agent_kept", 0.99),
            ])));
        let w = EpisodeRow::new("epoch-0002", 100_000, Branch::WorldModel, 0.5, 0.475, 0.4, 0.95, 300)
            .with_state(&goal)
            .with_scene(Some(&SceneCheck(vec![("agent_kept", 0.02)])));
        vec![r, w]
    }

    #[test]
    fn round_trips_with_types_and_nulls() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("episodes.parquet");
        write_episodes_parquet(&path, &rows().iter().collect::<Vec<_>>()).unwrap();
        let t = read_episodes_parquet(&path).unwrap();
        assert_eq!(t.len(), 2);
        // The fixed columns, the six of the state and the three checks.
        assert_eq!(t[0].len(), FIXED_COLUMNS + 6 + 3);
        let names: Vec<&str> = t[0].get_column_iter().map(|(n, _)| n.as_str()).skip(FIXED_COLUMNS).collect();
        let want = ["final_block_theta", "final_block_x", "final_block_y", "goal_theta", "goal_x", "goal_y"];
        assert_eq!(names[..6], want);
        assert_eq!(names[6..], ["agent_kept", "block_area", "goal_kept"]);
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
        assert_eq!(get(1, "max_raw"), Some(Field::Double(0.475)));
        // Same rows, same bytes.
        let again = dir.path().join("again.parquet");
        write_episodes_parquet(&again, &rows().iter().collect::<Vec<_>>()).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), std::fs::read(&again).unwrap());
    }

    #[test]
    fn a_task_without_named_columns_has_the_fixed_ones_and_a_bad_name_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("episodes.parquet");
        let plain = EpisodeRow::new("p", 1, Branch::Sim, 1.0, 1.0, 1.0, 0.5, 4);
        write_episodes_parquet(&path, &[&plain]).unwrap();
        assert_eq!(read_episodes_parquet(&path).unwrap()[0].len(), FIXED_COLUMNS);
        for bad in ["x y", "score", "9lives"] {
            let row = plain.clone().with_state(&[(bad, 0.0)]);
            let e = write_episodes_parquet(&path, &[&row]).unwrap_err().to_string();
            assert!(e.contains(&format!("{bad:?}")) && e.contains("episodes.parquet"), "{e}");
        }
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
