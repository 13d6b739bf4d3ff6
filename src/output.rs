//! Output folders: the run layer's [`runner::output`] (staging, resumable run folders,
//! inputs checked before outputs, one writer per output), re-exported for the
//! commands, and the JSON helpers they write their small files with.

pub use runner::output::lock;
pub use runner::output::{Inputs, RunDir, Staged, make_owned};

use std::path::Path;

use anyhow::{Context, Result};

/// Writes pretty JSON to a file.
pub fn write_json<T: serde::Serialize + ?Sized>(path: &Path, value: &T) -> Result<()> {
    let mut text = serde_json::to_string_pretty(value)?;
    text.push('\n');
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}
