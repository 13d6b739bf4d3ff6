//! `evalharness agreement --csv FILE`: agreement metrics for any predictor of policy
//! scores, read from a CSV.
//!
//! The CSV has a header with (at least) the columns `policy,predicted,actual`; each
//! row is one episode (or one policy's aggregate). Per-policy scores are the means
//! of their rows, in order of first appearance. With at least two rows for every
//! policy, 95% intervals come from the paired, stratified bootstrap (episodes
//! resampled within each policy); otherwise they are null.

use std::path::{Path, PathBuf};

use harness::metrics::agreement;
use harness::metrics::bootstrap::agreement_ci;
use serde_json::json;

/// A CSV `agreement` cannot read.
#[derive(Debug, thiserror::Error)]
pub enum AgreementError {
    /// The file, its header or a row that the CSV reader refuses.
    #[error("{}{}: {source}", path.display(), line.map_or(String::new(), |l| format!(": line {l}")))]
    Csv {
        /// The file.
        path: PathBuf,
        /// The line (1 is the header), where known.
        line: Option<usize>,
        /// The reader's error.
        source: csv::Error,
    },
    /// A column the metrics need is not in the header.
    #[error("{}: no column '{name}' (header: {header})", path.display())]
    Column {
        /// The file.
        path: PathBuf,
        /// The missing column.
        name: String,
        /// The header as it is.
        header: String,
    },
    /// A row whose values cannot be used.
    #[error("{}: line {line}: {message}", path.display())]
    Line {
        /// The file.
        path: PathBuf,
        /// The line (1 is the header).
        line: usize,
        /// What is wrong with it.
        message: String,
    },
    /// No row after the header.
    #[error("{}: no rows", path.display())]
    NoRows {
        /// The file.
        path: PathBuf,
    },
}

/// One policy's rows.
pub struct PolicyRows {
    name: String,
    predicted: Vec<f64>,
    actual: Vec<f64>,
}

/// Per-policy episode scores read from the CSV, in order of first appearance.
///
/// # Errors
/// A file that cannot be read, a missing column, a row whose value is not a finite number
/// or whose policy is empty (naming the line), or no rows.
pub fn read_csv(path: &Path) -> Result<Vec<PolicyRows>, AgreementError> {
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|source| AgreementError::Csv { path: path.to_path_buf(), line: None, source })?;
    let headers = reader
        .headers()
        .map_err(|source| AgreementError::Csv { path: path.to_path_buf(), line: Some(1), source })?
        .clone();
    let col = |name: &str| {
        headers.iter().position(|h| h == name).ok_or_else(|| AgreementError::Column {
            path: path.to_path_buf(),
            name: name.to_string(),
            header: headers.iter().collect::<Vec<_>>().join(","),
        })
    };
    let (cp, cs, ca) = (col("policy")?, col("predicted")?, col("actual")?);
    let mut out: Vec<PolicyRows> = Vec::new();
    for (k, rec) in reader.records().enumerate() {
        let line = k + 2; // 1-based, after the header
        let rec =
            rec.map_err(|source| AgreementError::Csv { path: path.to_path_buf(), line: Some(line), source })?;
        let bad = |message: String| AgreementError::Line { path: path.to_path_buf(), line, message };
        let get = |c: usize, name: &str| -> Result<f64, AgreementError> {
            let text = rec.get(c).unwrap_or("");
            let v: f64 = text.parse().map_err(|_| bad(format!("{name} '{text}' is not a number")))?;
            if !v.is_finite() {
                return Err(bad(format!("{name} is {v}")));
            }
            Ok(v)
        };
        let (p, a) = (get(cs, "predicted")?, get(ca, "actual")?);
        let name = rec.get(cp).unwrap_or("").to_string();
        if name.is_empty() {
            return Err(bad("empty policy name".into()));
        }
        match out.iter_mut().find(|r| r.name == name) {
            Some(r) => {
                r.predicted.push(p);
                r.actual.push(a);
            }
            None => out.push(PolicyRows { name, predicted: vec![p], actual: vec![a] }),
        }
    }
    if out.is_empty() {
        return Err(AgreementError::NoRows { path: path.to_path_buf() });
    }
    Ok(out)
}

/// The agreement of the CSV at `csv` as JSON: each policy's mean predicted and actual
/// score, the metrics with their bootstrap intervals (`bootstrap` replicates from `seed`),
/// and how they were drawn.
///
/// # Errors
/// A CSV that cannot be read ([`read_csv`]).
pub fn agreement_json(csv: &Path, bootstrap: usize, seed: u64) -> Result<serde_json::Value, AgreementError> {
    let policies = read_csv(csv)?;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let pred: Vec<f64> = policies.iter().map(|p| mean(&p.predicted)).collect();
    let act: Vec<f64> = policies.iter().map(|p| mean(&p.actual)).collect();
    if policies.len() < 2 {
        tracing::warn!("only one policy: correlations are undefined");
    }
    let m = agreement(&pred, &act);
    let ci = if policies.iter().all(|p| p.predicted.len() >= 2) {
        let pairs: Vec<(Vec<f64>, Vec<f64>)> =
            policies.iter().map(|p| (p.predicted.clone(), p.actual.clone())).collect();
        Some(agreement_ci(&pairs, bootstrap, seed))
    } else {
        None
    };
    let names: Vec<&str> = policies.iter().map(|p| p.name.as_str()).collect();
    Ok(json!({
        "csv": csv.display().to_string(),
        "policies": policies.iter().zip(pred.iter().zip(&act)).map(|(p, (s, g))| json!({
            "name": p.name, "rows": p.predicted.len(), "predicted": s, "actual": g,
        })).collect::<Vec<_>>(),
        "agreement": m.to_json(&names, ci.as_ref()),
        "bootstrap": {"replicates": bootstrap, "seed": seed, "scheme": "paired, stratified by policy (episodes resampled within each policy)"},
    }))
}
