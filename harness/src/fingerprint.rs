//! Content fingerprints of model folders, so that a resumed or extended run can tell
//! that a checkpoint it ranked before still holds the same weights.
//!
//! A folder's fingerprint is the SHA-256 of the files that define the model — every
//! `*.bpk` weight file and the `config.json` / `policy.json` settings at its top
//! level — taken in name order, each as its name, its length and its bytes. Files
//! that tools append to without changing the model (`provenance.json`, training logs,
//! pictures) do not count, so `simulate --record-scores` leaves it unchanged.

use std::fs;
use std::io::Read;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

/// A folder that cannot be fingerprinted.
#[derive(Debug, thiserror::Error)]
#[error("fingerprinting {path}: {source}")]
pub struct FingerprintError {
    /// The folder or file.
    pub path: PathBuf,
    /// The I/O error.
    pub source: std::io::Error,
}

/// The error of an I/O failure on `path`.
fn err(path: &Path) -> impl FnOnce(std::io::Error) -> FingerprintError + '_ {
    move |source| FingerprintError { path: path.to_path_buf(), source }
}

/// Whether `name` is part of what a folder's model is.
fn defines_the_model(name: &str) -> bool {
    name.ends_with(".bpk") || name == "config.json" || name == "policy.json"
}

/// `sha256:<hex>` of the model files in `dir` (see the module docs).
///
/// # Errors
/// [`FingerprintError`] naming the folder or file that could not be read.
pub fn folder(dir: &Path) -> Result<String, FingerprintError> {
    let mut names: Vec<String> = fs::read_dir(dir)
        .map_err(err(dir))?
        .filter_map(Result::ok)
        .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
        .filter_map(|e| e.file_name().into_string().ok())
        .filter(|n| defines_the_model(n))
        .collect();
    names.sort();
    let mut h = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    for name in names {
        let path = dir.join(&name);
        let mut f = fs::File::open(&path).map_err(err(&path))?;
        let len = f.metadata().map_err(err(&path))?.len();
        h.update((name.len() as u64).to_le_bytes());
        h.update(name.as_bytes());
        h.update(len.to_le_bytes());
        loop {
            let n = f.read(&mut buf).map_err(err(&path))?;
            if n == 0 {
                break;
            }
            h.update(&buf[..n]);
        }
    }
    let hex: String = h.finalize().iter().map(|b| format!("{b:02x}")).collect();
    Ok(format!("sha256:{hex}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_and_settings_count_provenance_does_not() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        fs::write(d.join("policy.json"), b"{}").unwrap();
        fs::write(d.join("model.bpk"), b"weights").unwrap();
        let a = folder(d).unwrap();
        assert!(a.starts_with("sha256:") && a.len() == 7 + 64, "{a}");
        fs::write(d.join("provenance.json"), b"{\"mujoco_score\": 1}").unwrap();
        assert_eq!(folder(d).unwrap(), a);
        fs::write(d.join("model.bpk"), b"weightz").unwrap();
        assert_ne!(folder(d).unwrap(), a);
        // The empty folder: SHA-256 of no bytes (the well-known e3b0c442... digest).
        let empty = tempfile::tempdir().unwrap();
        assert_eq!(
            folder(empty.path()).unwrap(),
            "sha256:e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"
        );
        assert!(folder(&d.join("missing")).unwrap_err().to_string().contains("missing"));
    }
}
