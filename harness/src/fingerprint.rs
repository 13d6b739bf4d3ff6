//! Content fingerprints of model folders, so that a resumed or extended run can tell
//! that a checkpoint it ranked before still holds the same weights.
//!
//! A folder's fingerprint is the SHA-256 of the files that define the model — every
//! `*.bpk` weight file and the `config.json` / `policy.json` settings at its top
//! level — taken in name order, each as its name, its length and its bytes. Files
//! that tools append to without changing the model (`provenance.json`, training logs,
//! pictures) do not count, so `simulate --record-scores` leaves it unchanged. A
//! rule judge's `judge.json` defines it as weights define a network, so it counts.
//! Files are read through symbolic links: a linked weight file is fingerprinted by
//! the bytes it points to, and a dangling link is an error, never an empty input.
//!
//! [`file`] fingerprints one input file (a scenario TOML) by its bytes alone.

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
    name.ends_with(".bpk") || name == "config.json" || name == "policy.json" || name == "judge.json"
}

/// `sha256:<hex>` of one file's bytes, read through symbolic links.
///
/// # Errors
/// [`FingerprintError`] naming the file that could not be read.
pub fn file(path: &Path) -> Result<String, FingerprintError> {
    let mut h = Sha256::new();
    feed(&mut h, &mut fs::File::open(path).map_err(err(path))?, path)?;
    Ok(hex(h))
}

/// `sha256:<hex>` of `bytes`.
pub fn bytes(bytes: &[u8]) -> String {
    let mut h = Sha256::new();
    h.update(bytes);
    hex(h)
}

/// Hashes the rest of the open file `f` (at `path`, for errors) into `h`.
fn feed(h: &mut Sha256, f: &mut fs::File, path: &Path) -> Result<(), FingerprintError> {
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = f.read(&mut buf).map_err(err(path))?;
        if n == 0 {
            return Ok(());
        }
        h.update(&buf[..n]);
    }
}

/// `sha256:<hex>` of a finished hash.
fn hex(h: Sha256) -> String {
    let hex: String = h.finalize().iter().map(|b| format!("{b:02x}")).collect();
    format!("sha256:{hex}")
}

/// `sha256:<hex>` of the model files in `dir` (see the module docs).
///
/// # Errors
/// [`FingerprintError`] naming the folder or file that could not be read.
pub fn folder(dir: &Path) -> Result<String, FingerprintError> {
    let mut names: Vec<String> = Vec::new();
    for entry in fs::read_dir(dir).map_err(err(dir))? {
        let entry = entry.map_err(err(dir))?;
        let Ok(name) = entry.file_name().into_string() else { continue };
        if !defines_the_model(&name) {
            continue;
        }
        // `DirEntry::file_type` does not follow links, so a linked weight file would
        // be skipped and the model fingerprinted as nothing; `metadata` follows them.
        let path = dir.join(&name);
        if fs::metadata(&path).map_err(err(&path))?.is_file() {
            names.push(name);
        }
    }
    names.sort();
    let mut h = Sha256::new();
    for name in names {
        let path = dir.join(&name);
        let mut f = fs::File::open(&path).map_err(err(&path))?;
        let len = f.metadata().map_err(err(&path))?.len();
        h.update((name.len() as u64).to_le_bytes());
        h.update(name.as_bytes());
        h.update(len.to_le_bytes());
        feed(&mut h, &mut f, &path)?;
    }
    Ok(hex(h))
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

    #[test]
    fn links_are_followed_and_a_rule_judge_counts() {
        // At 92f9f2b a folder of linked weights had the empty folder's fingerprint
        // (e3b0c442...), and `judge.json` was not read at all.
        let dir = tempfile::tempdir().unwrap();
        let (src, linked) = (dir.path().join("src"), dir.path().join("linked"));
        fs::create_dir_all(&src).unwrap();
        fs::create_dir_all(&linked).unwrap();
        fs::write(src.join("model.bpk"), b"weights").unwrap();
        std::os::unix::fs::symlink(src.join("model.bpk"), linked.join("model.bpk")).unwrap();
        assert_eq!(folder(&linked).unwrap(), folder(&src).unwrap());
        fs::write(src.join("model.bpk"), b"weightz").unwrap();
        assert_eq!(folder(&linked).unwrap(), folder(&src).unwrap(), "the link's target is read");
        std::os::unix::fs::symlink(dir.path().join("gone.bpk"), linked.join("gone.bpk")).unwrap();
        assert!(folder(&linked).unwrap_err().to_string().contains("gone.bpk"), "a dangling link is an error");
        let judge = dir.path().join("judge");
        fs::create_dir_all(&judge).unwrap();
        fs::write(judge.join("judge.json"), b"{\"threshold\": 0.9}").unwrap();
        let a = folder(&judge).unwrap();
        fs::write(judge.join("judge.json"), b"{\"threshold\": 0.5}").unwrap();
        assert_ne!(folder(&judge).unwrap(), a);
        // One file: SHA-256 of "abc" is ba7816bf... (FIPS 180-2's example).
        fs::write(dir.path().join("s.toml"), b"abc").unwrap();
        assert_eq!(
            file(&dir.path().join("s.toml")).unwrap(),
            "sha256:ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}
