//! `evalharness tasks`: several runs' headline numbers in one table. (A run's own
//! report is `runner::report`.)

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use harness::results::RankResults;
use reports::summary::Summary;

/// `evalharness tasks`: one row per run's `results.json`, Markdown on stdout and,
/// with `tex`, booktabs LaTeX in that file.
///
/// # Errors
/// A run folder without a readable `results.json` (named), or an unwritable `tex`.
pub fn run(runs: &[PathBuf], tex: Option<&Path>, force: bool) -> Result<std::process::ExitCode> {
    use reports::tasks::{TaskRow, latex_tasks, markdown_tasks};
    // Inputs before outputs: the LaTeX file is neither a run folder nor inside one (its
    // results.json would be overwritten), and an existing file is kept without --force.
    if let Some(path) = tex {
        crate::output::Inputs::new().all("RUN", runs).check(path)?;
        if std::fs::symlink_metadata(path).is_ok() && !force {
            bail!("--tex {} already exists (pass --force to replace it)", path.display());
        }
    }
    let rows = runs
        .iter()
        .map(|dir| {
            let r = RankResults::read(&dir.join("results.json"))?;
            Ok(TaskRow { summary: Summary::from_results(&r), minutes: Some(r.timing.wall_seconds / 60.0) })
        })
        .collect::<Result<Vec<_>>>()?;
    if let Some(path) = tex {
        harness::runfile::write_atomic(path, &latex_tasks(&rows))
            .map_err(|e| anyhow::anyhow!("writing {}: {}", e.path.display(), e.message))?;
    }
    out!("{}", markdown_tasks(&rows));
    Ok(std::process::ExitCode::SUCCESS)
}
