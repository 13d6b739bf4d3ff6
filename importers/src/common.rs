//! The JSON writer of the import commands' small files (`import.json`).

use std::path::Path;

use crate::error::{Context, ImportCmdError, Result};

/// Writes pretty JSON to a file.
///
/// # Errors
/// A value that cannot be encoded, or a file that cannot be written, naming it.
pub(crate) fn write_json<T: serde::Serialize + ?Sized>(path: &Path, value: &T) -> Result<()> {
    let mut text = serde_json::to_string_pretty(value)
        .map_err(|source| ImportCmdError::Json { path: path.to_path_buf(), source })?;
    text.push('\n');
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}
