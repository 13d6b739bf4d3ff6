//! "Inputs before outputs": what a command reads, checked against where it writes
//! before anything is written.
//!
//! Every command that takes `--out` lists its inputs in an [`Inputs`] (each path with
//! the flag that named it) and hands it to [`super::Staged::new`] or
//! [`super::RunDir::prepare`], which refuse an `--out` that is, lies inside or contains
//! an input, and an input that is one of the folders the tool itself keeps beside
//! `--out` (`OUT.partial`, `OUT.replaced`, `OUT.shards`): replacing or clearing those
//! would delete the input. Inputs given by name rather than path (`--scenario lift`)
//! are not files and are not listed. A world model lists its autoencoder folder too,
//! which its `config.json` names.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use super::OutputError;
use super::lock::absolute;

type Result<T, E = OutputError> = std::result::Result<T, E>;

/// The names of the folders the tool keeps beside an output `OUT` (see the module docs).
pub const OWNED_SUFFIXES: [&str; 3] = [".partial", ".replaced", ".shards"];

/// The paths a command reads, each with the flag that named it.
#[derive(Clone, Debug, Default)]
pub struct Inputs {
    list: Vec<(String, PathBuf)>,
}

impl Inputs {
    /// No inputs yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds `path`, named by `flag`.
    pub fn add(mut self, flag: &str, path: &Path) -> Self {
        self.list.push((flag.to_string(), path.to_path_buf()));
        self
    }

    /// Adds `path` when there is one.
    pub fn maybe(self, flag: &str, path: Option<&Path>) -> Self {
        match path {
            Some(p) => self.add(flag, p),
            None => self,
        }
    }

    /// Adds every path of `paths`.
    pub fn all(self, flag: &str, paths: &[PathBuf]) -> Self {
        paths.iter().fold(self, |acc, p| acc.add(flag, p))
    }

    /// Adds `--scenario`'s file when it names one (a name such as `lift` is not a file).
    pub fn scenario(self, scenario: &str) -> Self {
        let p = Path::new(scenario);
        if p.is_file() { self.add("--scenario", p) } else { self }
    }

    /// Adds a world model folder and the autoencoder folder its `config.json` names.
    pub fn world_model(self, flag: &str, dir: &Path) -> Self {
        let ae = world_model::model::WorldModelConfig::read(dir)
            .ok()
            .and_then(|c| c.autoencoder)
            .map(|ae| dir.join(ae));
        self.add(flag, dir).maybe(&format!("{flag}'s autoencoder"), ae.as_deref())
    }

    /// Refuses an `out` that overlaps an input, naming both.
    ///
    /// # Errors
    /// The first overlap.
    pub fn check(&self, out: &Path) -> Result<()> {
        let o = absolute(out);
        for (flag, input) in &self.list {
            let i = absolute(input);
            let how = if o == i {
                "is"
            } else if o.starts_with(&i) {
                "lies inside"
            } else if i.starts_with(&o) {
                "contains"
            } else {
                continue;
            };
            return Err(OutputError::Overlaps {
                out: out.to_path_buf(),
                how,
                flag: flag.clone(),
                input: input.clone(),
            });
        }
        Ok(())
    }

    /// Refuses an input that is, lies inside or contains the folder `OUT{suffix}` that
    /// the command keeps beside `out` and clears or replaces (one of
    /// [`OWNED_SUFFIXES`]), naming both.
    ///
    /// # Errors
    /// The first such input.
    pub fn check_kept(&self, out: &Path, suffix: &str) -> Result<()> {
        debug_assert!(OWNED_SUFFIXES.contains(&suffix), "{suffix} is not a folder the tool keeps");
        let kept = sibling(&absolute(out), suffix);
        for (flag, input) in &self.list {
            let i = absolute(input);
            if i == kept || i.starts_with(&kept) || kept.starts_with(&i) {
                return Err(OutputError::InputKept {
                    flag: flag.clone(),
                    input: input.clone(),
                    suffix: suffix.to_string(),
                    out: out.to_path_buf(),
                });
            }
        }
        Ok(())
    }

    /// Everything an output must pass before it is touched: `out` apart from every
    /// input ([`Inputs::check`]), no input where the command keeps `OUT{kept}`
    /// ([`Inputs::check_kept`]), and `out` not a dangling link.
    ///
    /// # Errors
    /// The first of those that fails.
    pub fn refuse(&self, out: &Path, kept: &str) -> Result<()> {
        self.check(out)?;
        self.check_kept(out, kept)?;
        check_not_dangling(out)
    }

    /// [`Inputs::refuse`], then the output's lock ([`super::lock`]), held while the
    /// returned guard lives.
    ///
    /// # Errors
    /// As [`Inputs::refuse`], or another process writing `out`.
    pub fn claim(&self, out: &Path, kept: &str) -> Result<super::lock::OutLock> {
        self.refuse(out, kept)?;
        super::lock::lock(out)
    }
}

/// `path` with `suffix` appended to its last component (`out` -> `out.replaced`).
pub fn sibling(path: &Path, suffix: &str) -> PathBuf {
    let mut s: OsString = path.as_os_str().to_owned();
    s.push(suffix);
    PathBuf::from(s)
}

/// Refuses an `--out` that is a symbolic link to nothing: creating the folder would
/// fail (or land elsewhere), and a failed run must not delete the user's link.
///
/// # Errors
/// A dangling link, naming it and its target.
fn check_not_dangling(out: &Path) -> Result<()> {
    let is_link = std::fs::symlink_metadata(out).is_ok_and(|m| m.file_type().is_symlink());
    if is_link && std::fs::metadata(out).is_err() {
        let target = std::fs::read_link(out).map_or_else(|_| "?".into(), |t| t.display().to_string());
        return Err(OutputError::Dangling { out: out.to_path_buf(), target });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_input_where_the_tool_keeps_its_own_folders_is_refused() {
        // At 92f9f2b `dataset merge X.partial Y --out X` cleared its own input X.partial.
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let e = Inputs::new().add("dataset", &d.join("x.partial")).check_kept(&d.join("x"), ".partial");
        assert!(e.unwrap_err().to_string().contains("keeps .partial files"));
        let e = Inputs::new().add("--policies", &d.join("o.shards/p")).check_kept(&d.join("o"), ".shards");
        assert!(e.unwrap_err().to_string().contains(".shards"));
        Inputs::new().add("dataset", &d.join("x.partial2")).check_kept(&d.join("x"), ".partial").unwrap();
        let e = Inputs::new().add("--policy", &d.join("p")).check(&d.join("p/out")).unwrap_err();
        assert!(e.to_string().contains("lies inside the input --policy"), "{e}");
    }

    #[test]
    fn a_world_models_autoencoder_is_an_input() {
        // At 92f9f2b `wm eval --out AUTOENCODER --force` deleted the autoencoder.
        let dir = tempfile::tempdir().unwrap();
        let wm = dir.path().join("wm");
        std::fs::create_dir_all(&wm).unwrap();
        let unet = world_model::unet::UNetConfig::new(3, 8, vec![1], vec![]).with_groups(4);
        let mut cfg = world_model::model::WorldModelConfig::pixels(unet, 96);
        cfg.autoencoder = Some(PathBuf::from("../ae"));
        let file = serde_json::json!({ "model": cfg });
        std::fs::write(wm.join("config.json"), file.to_string()).unwrap();
        let inputs = Inputs::new().world_model("--world-model", &wm);
        let e = inputs.check(&dir.path().join("ae")).unwrap_err().to_string();
        assert!(e.contains("--world-model's autoencoder"), "{e}");
    }

    #[test]
    fn a_dangling_link_is_refused_naming_its_target() {
        let dir = tempfile::tempdir().unwrap();
        let link = dir.path().join("out");
        std::os::unix::fs::symlink(dir.path().join("nowhere"), &link).unwrap();
        let e = check_not_dangling(&link).unwrap_err().to_string();
        assert!(e.contains("nowhere") && e.contains("does not exist"), "{e}");
        check_not_dangling(&dir.path().join("fresh")).unwrap();
    }
}
