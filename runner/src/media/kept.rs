//! The filmstrip frames a run keeps: per policy, those of the best- and worst-agreeing
//! episode among the batches run so far (what [`super::pick_seeds`] can pick),
//! in memory and in the run's `filmstrip-frames/` folder, so that a resumed run, or the
//! run that joins `--processes` shards, finds the episodes its earlier processes made
//! instead of replaying them. The run removes the folder once its filmstrips are written.
//!
//! A file, `filmstrip-frames/<policy>/<seed>.frames`: the magic `EHFRAMES1`, then as
//! little-endian u32s the number of MuJoCo frames, of imagined frames and the bytes of
//! one frame, then the frames.

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use engine::schedule::EpisodeFrames;
use harness::results::{Branch, EpisodeRow};

use crate::error::RunError;

type Result<T, E = RunError> = std::result::Result<T, E>;

/// The folder of a run's kept frames.
pub const FOLDER: &str = "filmstrip-frames";

const MAGIC: &[u8] = b"EHFRAMES1";

/// An episode's |imagined − real| score and its seed.
type Gap = (f64, u64);

/// |imagined − real| score of each seed of `policy` that has both rows, with the seed.
pub(super) fn gaps(rows: &[EpisodeRow], policy: &str) -> Vec<Gap> {
    let mut gaps: Vec<Gap> = Vec::new();
    for r in rows.iter().filter(|r| r.policy == policy && r.branch == Branch::Sim) {
        if let Some(w) =
            rows.iter().find(|w| w.policy == policy && w.seed == r.seed && w.branch == Branch::WorldModel)
        {
            gaps.push(((w.score - r.score).abs(), r.seed));
        }
    }
    gaps
}

/// The order [`pick_seeds`] sorts by: the gap, then the seed.
pub(super) fn order(a: Gap, b: Gap) -> std::cmp::Ordering {
    a.0.total_cmp(&b.0).then(a.1.cmp(&b.1))
}

/// Per policy, the recorded frames of the best- and worst-agreeing episode among the
/// batches of this run: what [`super::pick_seeds`] can pick from them, and nothing
/// else (two episodes per policy at most). With a folder, each kept episode is also a file
/// there.
#[derive(Default)]
pub struct Kept {
    by_policy: HashMap<String, Vec<(Gap, EpisodeFrames)>>,
    dir: Option<PathBuf>,
}

impl Kept {
    /// Kept frames saved in `dir` as well, starting from those an earlier process of the
    /// run saved there for episodes among `rows` (others are removed: their batch was
    /// not finished, so it runs again).
    ///
    /// # Errors
    /// A folder or file that cannot be read or written, or a damaged file, naming it.
    pub fn open(dir: &Path, rows: &[EpisodeRow]) -> Result<Self> {
        let mut kept = Self { by_policy: HashMap::new(), dir: Some(dir.to_path_buf()) };
        if !dir.is_dir() {
            return Ok(kept);
        }
        for entry in read_dir(dir)? {
            let policy = entry.file_name().to_string_lossy().into_owned();
            let mut frames = Vec::new();
            for file in read_dir(&entry.path())? {
                frames.push(read(&file.path())?);
            }
            kept.add(&policy, rows, frames)?;
        }
        Ok(kept)
    }

    /// Takes a finished batch of `policy`: its rows and recorded frames.
    ///
    /// # Errors
    /// A kept episode's file that cannot be written or removed.
    pub fn add(&mut self, policy: &str, rows: &[EpisodeRow], frames: Vec<EpisodeFrames>) -> Result<()> {
        let gaps = gaps(rows, policy);
        let kept = self.by_policy.entry(policy.to_string()).or_default();
        let mut new = Vec::new();
        for f in frames {
            match gaps.iter().find(|g| g.1 == f.seed) {
                Some(&g) if !kept.iter().any(|k| k.1.seed == f.seed) => {
                    new.push(f.seed);
                    kept.push((g, f));
                }
                _ => {
                    if let Some(dir) = &self.dir {
                        remove(&file(dir, policy, f.seed))?;
                    }
                }
            }
        }
        let lo = kept.iter().map(|k| k.0).min_by(|a, b| order(*a, *b));
        let hi = kept.iter().map(|k| k.0).max_by(|a, b| order(*a, *b));
        let (stay, gone): (Vec<_>, Vec<_>) = kept.drain(..).partition(|k| Some(k.0) == lo || Some(k.0) == hi);
        *kept = stay;
        if let Some(dir) = &self.dir {
            for (_, f) in &gone {
                remove(&file(dir, policy, f.seed))?;
            }
            for (_, f) in kept.iter().filter(|k| new.contains(&k.1.seed)) {
                write(&file(dir, policy, f.seed), f)?;
            }
        }
        Ok(())
    }

    /// The kept frames of `policy`'s `seed`, if the run recorded them.
    pub fn get(&self, policy: &str, seed: u64) -> Option<&EpisodeFrames> {
        self.by_policy.get(policy)?.iter().map(|k| &k.1).find(|f| f.seed == seed)
    }
}

/// Moves the kept frames of each of `shards` (their run folders) into `out`'s folder, for
/// the run that joins them ([`Kept::open`] keeps what the joined rows pick).
///
/// # Errors
/// A file that cannot be moved.
pub fn gather(shards: &[PathBuf], out: &Path) -> Result<()> {
    for shard in shards {
        let from = shard.join(FOLDER);
        if !from.is_dir() {
            continue;
        }
        for policy in read_dir(&from)? {
            let to = out.join(FOLDER).join(policy.file_name());
            std::fs::create_dir_all(&to).map_err(RunError::file(format!("creating {}", to.display())))?;
            for f in read_dir(&policy.path())? {
                let dest = to.join(f.file_name());
                std::fs::rename(f.path(), &dest).map_err(RunError::file(format!(
                    "moving {} to {}",
                    f.path().display(),
                    dest.display()
                )))?;
            }
        }
    }
    Ok(())
}

fn file(dir: &Path, policy: &str, seed: u64) -> PathBuf {
    dir.join(policy).join(format!("{seed}.frames"))
}

fn read_dir(dir: &Path) -> Result<Vec<std::fs::DirEntry>> {
    let reading = || RunError::file(format!("reading {}", dir.display()));
    let mut v: Vec<std::fs::DirEntry> =
        std::fs::read_dir(dir).map_err(reading())?.collect::<std::io::Result<_>>().map_err(reading())?;
    v.sort_by_key(std::fs::DirEntry::file_name);
    Ok(v)
}

fn remove(path: &Path) -> Result<()> {
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            Err(RunError::file(format!("removing {}", path.display()))(e))
        }
        _ => Ok(()),
    }
}

/// Writes `f` to `path` whole (a temporary file renamed), so a killed run leaves no half file.
fn write(path: &Path, f: &EpisodeFrames) -> Result<()> {
    let bad = |why: String| RunError::Kept { path: path.to_path_buf(), why };
    let dir = path.parent().ok_or_else(|| bad("it has no folder".into()))?;
    std::fs::create_dir_all(dir).map_err(RunError::file(format!("creating {}", dir.display())))?;
    let len = f.real.iter().chain(&f.imagined).map(Vec::len).max().unwrap_or(0);
    if f.real.iter().chain(&f.imagined).any(|x| x.len() != len) {
        return Err(bad(format!("the frames of seed {} differ in size", f.seed)));
    }
    let mut bytes = Vec::with_capacity(MAGIC.len() + 12 + len * (f.real.len() + f.imagined.len()));
    bytes.extend_from_slice(MAGIC);
    for n in [f.real.len(), f.imagined.len(), len] {
        let n = u32::try_from(n).map_err(|_| bad(format!("{n} frames or bytes do not fit its header")))?;
        bytes.extend_from_slice(&n.to_le_bytes());
    }
    f.real.iter().chain(&f.imagined).for_each(|x| bytes.extend_from_slice(x));
    let tmp = path.with_extension("tmp");
    let mut out =
        std::fs::File::create(&tmp).map_err(RunError::file(format!("creating {}", tmp.display())))?;
    out.write_all(&bytes).map_err(RunError::file(format!("writing {}", tmp.display())))?;
    std::fs::rename(&tmp, path).map_err(RunError::file(format!(
        "renaming {} to {}",
        tmp.display(),
        path.display()
    )))
}

/// Reads a file [`write`] wrote; its seed is its name.
fn read(path: &Path) -> Result<EpisodeFrames> {
    let bad = |why: &str| RunError::Kept { path: path.to_path_buf(), why: why.to_string() };
    let seed: u64 = path
        .file_stem()
        .and_then(|s| s.to_str())
        .and_then(|s| s.parse().ok())
        .filter(|_| path.extension().is_some_and(|e| e == "frames"))
        .ok_or_else(|| bad("its name is not <seed>.frames"))?;
    let bytes = std::fs::read(path).map_err(RunError::file(format!("reading {}", path.display())))?;
    let rest = bytes.strip_prefix(MAGIC).ok_or_else(|| bad("no magic"))?;
    if rest.len() < 12 {
        return Err(bad("truncated header"));
    }
    let n = |i: usize| u32::from_le_bytes([rest[i], rest[i + 1], rest[i + 2], rest[i + 3]]) as usize;
    let (real, imagined, len) = (n(0), n(4), n(8));
    let body = &rest[12..];
    if len == 0 || body.len() != (real + imagined).saturating_mul(len) {
        return Err(bad("its size does not match its header"));
    }
    let mut frames = body.chunks_exact(len).map(<[u8]>::to_vec);
    Ok(EpisodeFrames { seed, real: frames.by_ref().take(real).collect(), imagined: frames.collect() })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(seed: u64, b: Branch, s: f64) -> EpisodeRow {
        EpisodeRow::new("p", seed, b, s, 0.0, 0.0, 0.95, 1)
    }

    fn frames(seeds: &[u64]) -> Vec<EpisodeFrames> {
        seeds
            .iter()
            .map(|&seed| EpisodeFrames {
                seed,
                real: vec![vec![seed as u8; 3]],
                imagined: vec![vec![7; 3]; 2],
            })
            .collect()
    }

    #[test]
    fn kept_frames_are_those_pick_seeds_picks_and_survive_a_new_process() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join(FOLDER);
        // Batch 1: gaps 0.4 (seed 1) and 0.05 (seed 2). Batch 2: gaps 0.05 (seed 3, ties
        // seed 2 and loses on the seed) and 0.2 (seed 4, neither end).
        let b1 = vec![
            row(1, Branch::Sim, 0.5),
            row(1, Branch::WorldModel, 0.1),
            row(2, Branch::Sim, 0.5),
            row(2, Branch::WorldModel, 0.45),
        ];
        let b2 = vec![
            row(3, Branch::Sim, 0.5),
            row(3, Branch::WorldModel, 0.55),
            row(4, Branch::Sim, 0.5),
            row(4, Branch::WorldModel, 0.3),
        ];
        let mut kept = Kept::open(&dir, &[]).unwrap();
        kept.add("p", &b1, frames(&[1, 2])).unwrap();
        kept.add("p", &b2, frames(&[3, 4])).unwrap();
        let all: Vec<EpisodeRow> = b1.iter().chain(&b2).cloned().collect();
        assert_eq!(super::super::pick_seeds(&all, "p"), vec![(2, "best"), (1, "worst")]);
        assert!(kept.get("p", 1).is_some() && kept.get("p", 2).is_some());
        assert!(kept.get("p", 3).is_none() && kept.get("p", 4).is_none(), "only the two ends are kept");
        let mut files: Vec<String> = read_dir(&dir.join("p"))
            .unwrap()
            .iter()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        files.sort();
        assert_eq!(files, ["1.frames", "2.frames"]);
        // A new process of the run (a resume) finds them, byte for byte; with only batch 1's
        // rows (batch 2 was not finished), the same two.
        let again = Kept::open(&dir, &b1).unwrap();
        assert_eq!(again.get("p", 1), kept.get("p", 1));
        assert_eq!(again.get("p", 2), kept.get("p", 2));
        // A file whose episode has no rows (its batch runs again) is dropped.
        write(&file(&dir, "p", 9), &frames(&[9])[0]).unwrap();
        let again = Kept::open(&dir, &b1).unwrap();
        assert!(again.get("p", 9).is_none() && !file(&dir, "p", 9).exists());
    }

    #[test]
    fn a_damaged_kept_file_is_named() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("5.frames");
        write(&path, &frames(&[5])[0]).unwrap();
        assert_eq!(read(&path).unwrap(), frames(&[5])[0]);
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 1]).unwrap();
        let e = format!("{:#}", read(&path).unwrap_err());
        assert!(e.contains("5.frames") && e.contains("does not match"), "{e}");
        std::fs::write(&path, b"nonsense").unwrap();
        assert!(format!("{:#}", read(&path).unwrap_err()).contains("no magic"));
    }
}
