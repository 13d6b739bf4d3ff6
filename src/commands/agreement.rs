//! `evalharness agreement --csv FILE`: agreement metrics for any predictor.
//!
//! The CSV has a header with (at least) the columns `policy,predicted,actual`; each
//! row is one episode (or one policy's aggregate). Per-policy scores are the means
//! of their rows, in order of first appearance. With at least two rows for every
//! policy, 95% intervals come from the paired, stratified bootstrap (episodes
//! resampled within each policy); otherwise they are null.

use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use harness::metrics::agreement;
use harness::metrics::bootstrap::agreement_ci;
use serde_json::json;

use crate::cli::AgreementArgs;

/// One policy's rows.
pub(crate) struct PolicyRows {
    name: String,
    predicted: Vec<f64>,
    actual: Vec<f64>,
}

/// Per-policy episode scores read from the CSV, in order of first appearance.
pub(crate) fn read_csv(path: &Path) -> Result<Vec<PolicyRows>> {
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .with_context(|| format!("opening {}", path.display()))?;
    let headers =
        reader.headers().with_context(|| format!("reading the header of {}", path.display()))?.clone();
    let col = |name: &str| {
        headers.iter().position(|h| h == name).with_context(|| {
            format!(
                "{}: no column '{name}' (header: {})",
                path.display(),
                headers.iter().collect::<Vec<_>>().join(",")
            )
        })
    };
    let (cp, cs, ca) = (col("policy")?, col("predicted")?, col("actual")?);
    let mut out: Vec<PolicyRows> = Vec::new();
    for (k, rec) in reader.records().enumerate() {
        let line = k + 2; // 1-based, after the header
        let rec = rec.with_context(|| format!("{}: line {line}", path.display()))?;
        let get = |c: usize, name: &str| -> Result<f64> {
            let text = rec.get(c).unwrap_or("");
            let v: f64 = text.parse().with_context(|| {
                format!("{}: line {line}: {name} '{text}' is not a number", path.display())
            })?;
            if !v.is_finite() {
                bail!("{}: line {line}: {name} is {v}", path.display());
            }
            Ok(v)
        };
        let (p, a) = (get(cs, "predicted")?, get(ca, "actual")?);
        let name = rec.get(cp).unwrap_or("").to_string();
        if name.is_empty() {
            bail!("{}: line {line}: empty policy name", path.display());
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
        bail!("{}: no rows", path.display());
    }
    Ok(out)
}

/// Runs the command.
pub fn run(a: &AgreementArgs) -> Result<ExitCode> {
    let policies = read_csv(&a.csv)?;
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
        Some(agreement_ci(&pairs, a.bootstrap, a.seed))
    } else {
        None
    };
    let names: Vec<&str> = policies.iter().map(|p| p.name.as_str()).collect();
    let out = json!({
        "csv": a.csv.display().to_string(),
        "policies": policies.iter().zip(pred.iter().zip(&act)).map(|(p, (s, g))| json!({
            "name": p.name, "rows": p.predicted.len(), "predicted": s, "actual": g,
        })).collect::<Vec<_>>(),
        "agreement": m.to_json(&names, ci.as_ref()),
        "bootstrap": {"replicates": a.bootstrap, "seed": a.seed, "scheme": "paired, stratified by policy (episodes resampled within each policy)"},
    });
    outln!("{}", serde_json::to_string_pretty(&out)?);
    Ok(ExitCode::SUCCESS)
}
