//! A finished run's episode tables beside its `results.json`: `episodes.csv` (the
//! columns every task has) and `episodes.parquet` ([`crate::episodes`], every
//! column), the same rows sorted by (policy, seed, branch).

use std::path::Path;

use harness::results::EpisodeRow;

use crate::episodes::{TableError, write_episodes_parquet};

/// The columns of `episodes.csv`.
const CSV_COLUMNS: [&str; 8] =
    ["policy", "seed", "branch", "score", "max_raw", "final_raw", "success", "steps"];

/// Writes `episodes.csv` and `episodes.parquet` into `out`: `rows` sorted by (policy,
/// seed, branch).
///
/// # Errors
/// [`TableError`] naming the file that cannot be written.
pub fn write_tables(out: &Path, rows: &[EpisodeRow]) -> Result<(), TableError> {
    let mut sorted: Vec<&EpisodeRow> = rows.iter().collect();
    sorted.sort_by(|x, y| (&x.policy, x.seed, x.branch).cmp(&(&y.policy, y.seed, y.branch)));
    write_csv(&out.join("episodes.csv"), &sorted)?;
    write_episodes_parquet(&out.join("episodes.parquet"), &sorted)
}

/// Writes `sorted` as `episodes.csv` at `path` (scores with six decimals).
fn write_csv(path: &Path, sorted: &[&EpisodeRow]) -> Result<(), TableError> {
    let err = |e: &dyn std::fmt::Display| TableError { path: path.to_path_buf(), message: e.to_string() };
    let mut w = csv::Writer::from_path(path).map_err(|e| err(&e))?;
    w.write_record(CSV_COLUMNS).map_err(|e| err(&e))?;
    for r in sorted {
        w.write_record([
            r.policy.clone(),
            r.seed.to_string(),
            r.branch.as_str().to_string(),
            format!("{:.6}", r.score),
            format!("{:.6}", r.max_raw),
            format!("{:.6}", r.final_raw),
            r.success.to_string(),
            r.steps.to_string(),
        ])
        .map_err(|e| err(&e))?;
    }
    w.flush().map_err(|e| err(&e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use harness::results::Branch;

    #[test]
    fn the_csv_is_sorted_with_six_decimals() {
        let dir = tempfile::tempdir().unwrap();
        let rows = [
            EpisodeRow::new("b", 1, Branch::Sim, 0.5, 0.25, 0.125, 0.95, 10),
            EpisodeRow::new("a", 2, Branch::WorldModel, 1.0, 1.0, 1.0, 0.95, 7),
            EpisodeRow::new("a", 2, Branch::Sim, 1.0 / 3.0, 0.3, 0.2, 0.95, 9),
        ];
        write_tables(dir.path(), &rows).unwrap();
        let csv = std::fs::read_to_string(dir.path().join("episodes.csv")).unwrap();
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], "policy,seed,branch,score,max_raw,final_raw,success,steps");
        assert!(lines[1].starts_with("a,2,sim,0.333333,0.300000,0.200000,"), "{csv}");
        assert!(lines[2].starts_with("a,2,world_model,1.000000,"), "{csv}");
        assert!(lines[3].starts_with("b,1,sim,0.500000,0.250000,0.125000,"), "{csv}");
        assert!(dir.path().join("episodes.parquet").is_file());
    }
}
