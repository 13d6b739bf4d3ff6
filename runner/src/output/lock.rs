//! One writer per output: a command holds an exclusive lock on `--out` for as long as
//! it writes there, so two runs into the same folder (two `collect`s, a `rank` and its
//! `--resume` started twice) cannot mix their files. The second is refused at once,
//! naming the folder.
//!
//! The lock is the kernel's `flock` on a hidden file beside the output
//! (`.NAME.evalharness-lock`), released by the kernel if the process dies, so a killed
//! run never leaves a stale lock. The file is removed when the holder is done; a
//! taker checks after locking that the file it locked is still the one at the path
//! (not one a finishing holder just unlinked). A process that already holds the lock
//! (a `rank --processes` parent, whose finishing step writes the same output) takes
//! it again freely.

use std::collections::HashMap;
use std::fs::{File, OpenOptions, TryLockError};
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use super::OutputError;
use super::error::io;

/// The locks this process holds, by lock file, with their holders' count.
static HELD: Mutex<Option<HashMap<PathBuf, usize>>> = Mutex::new(None);

/// An exclusive hold on an output folder; released when dropped.
#[derive(Debug)]
pub struct OutLock {
    path: PathBuf,
    file: Option<File>,
}

/// The lock file of output `out`.
fn lock_path(out: &Path) -> PathBuf {
    let out = absolute(out);
    let name = out.file_name().map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
    out.with_file_name(format!(".{name}.evalharness-lock"))
}

/// Takes the lock on `out`.
///
/// # Errors
/// Another process holds it (naming the folder), or the lock file cannot be made.
pub fn lock(out: &Path) -> Result<OutLock, OutputError> {
    let path = lock_path(out);
    let mut held = HELD.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let held = held.get_or_insert_with(HashMap::new);
    if let Some(n) = held.get_mut(&path) {
        *n += 1;
        return Ok(OutLock { path, file: None });
    }
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(io(format!("creating {}", parent.display())))?;
    }
    for _ in 0..8 {
        let file = OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&path)
            .map_err(io(format!("creating the lock file {}", path.display())))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                return Err(OutputError::Locked { out: out.to_path_buf(), lock: path });
            }
            Err(TryLockError::Error(e)) => return Err(io(format!("locking {}", path.display()))(e)),
        }
        // The holder before us may have unlinked the file after we opened it: then the
        // lock is on a file nobody else will see; take the one at the path instead.
        let ours = file.metadata().map(|m| (m.dev(), m.ino())).ok();
        let at_path = std::fs::metadata(&path).map(|m| (m.dev(), m.ino())).ok();
        if ours.is_some() && ours == at_path {
            held.insert(path.clone(), 1);
            return Ok(OutLock { path, file: Some(file) });
        }
    }
    Err(OutputError::LockChanging { out: out.to_path_buf() })
}

impl Drop for OutLock {
    fn drop(&mut self) {
        let mut held = HELD.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        let Some(held) = held.as_mut() else { return };
        let Some(n) = held.get_mut(&self.path) else { return };
        *n -= 1;
        if *n == 0 {
            held.remove(&self.path);
            // Unlink first, then unlock (by closing): a waiting taker re-checks the path.
            let _ = std::fs::remove_file(&self.path);
            drop(self.file.take());
        }
    }
}

/// `p` as an absolute path with its existing part resolved (symbolic links, `..`),
/// so two spellings of one folder compare equal even when `p` does not exist yet.
pub fn absolute(p: &Path) -> PathBuf {
    let p = std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let mut tail = Vec::new();
    let mut head = p.as_path();
    loop {
        if let Ok(real) = head.canonicalize() {
            return tail.iter().rev().fold(real, |acc, c| acc.join(c));
        }
        match (head.parent(), head.file_name()) {
            (Some(parent), Some(name)) => {
                tail.push(name.to_os_string());
                head = parent;
            }
            _ => return p,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_process_is_refused_and_this_one_may_take_it_again() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let a = lock(&out).unwrap();
        let again = lock(&out).unwrap();
        drop(again);
        assert!(lock_path(&out).exists(), "still held by the first holder");
        // Another process's attempt, as the kernel sees it: a new open file description.
        let other = File::options().write(true).open(lock_path(&out)).unwrap();
        assert!(matches!(other.try_lock(), Err(TryLockError::WouldBlock)));
        drop(a);
        assert!(!lock_path(&out).exists(), "the lock file goes with the last holder");
        drop(lock(&out).unwrap());
    }
}
