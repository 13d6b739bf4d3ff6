//! The models a run reads (`rank`, `plan`, `simulate --replay-imagined`, `wm eval`),
//! loaded with the run's options applied and checked against its task, and their
//! content fingerprints, which `config.json` records so that `--resume` and `merge`
//! refuse rows of changed models.

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use harness::task::{ScoreKind, Task};
use policies::dir::checkpoint_name;
use policies::judge::{FrameJudge, Label};
use world_model::model::WorldModel;

use crate::error::RunError;

/// An input of a run, as `config.json`'s fingerprints name it: (name, path, the
/// SHA-256 of its content).
pub type Fingerprinted = (String, PathBuf, String);

/// Loads the world model in `dir`, with `--alpha` and `--noise-scale` applied when given.
///
/// # Errors
/// [`RunError::LoadWorldModel`] for an unloadable model, [`RunError::ModelOption`] for
/// an α or noise scale it cannot take, naming the folder.
pub fn load_world_model(
    dir: &Path,
    alpha: Option<f32>,
    noise_scale: Option<f32>,
    device: &Device,
) -> Result<WorldModel, RunError> {
    let mut wm = WorldModel::load(dir, device)
        .map_err(|source| RunError::LoadWorldModel { dir: dir.to_path_buf(), source: Box::new(source) })?;
    let option =
        |flag: &'static str| move |error| RunError::ModelOption { flag, dir: dir.to_path_buf(), error };
    if let Some(alpha) = alpha {
        wm.set_alpha(alpha).map_err(option("--alpha"))?;
    }
    if let Some(t) = noise_scale {
        wm.set_noise_scale(t).map_err(option("--noise-scale"))?;
    }
    Ok(wm)
}

/// Reads a judge folder, named in any error as the `--judge` it is (the loader's error
/// type is the policies', which says "policy X").
///
/// # Errors
/// [`RunError::JudgeFolder`]: a missing or invalid judge folder.
pub fn read_judge_folder(dir: &Path, device: &Device) -> Result<FrameJudge, RunError> {
    FrameJudge::load(dir, device).map_err(|e| RunError::JudgeFolder { path: e.path, message: e.message })
}

/// Loads `--judge`'s folder and checks that it reads the task's frames and scores what
/// the task scores.
///
/// # Errors
/// An unloadable judge ([`RunError::JudgeFolder`]), or one of another frame size or
/// score kind ([`RunError::JudgeMismatch`]), naming its folder.
pub fn load_judge(dir: &Path, task: &dyn Task, device: &Device) -> Result<FrameJudge, RunError> {
    let j = read_judge_folder(dir, device)?;
    let size = task.observation_spec().image_size;
    let mismatch = |what: String| RunError::JudgeMismatch { dir: dir.to_path_buf(), what };
    if j.image_size() != size {
        return Err(mismatch(format!(
            "reads {0}x{0} frames, the task renders {size}x{size}",
            j.image_size()
        )));
    }
    let fits = matches!(
        (j.file.label, task.score_kind()),
        (Label::Coverage, ScoreKind::Coverage { .. }) | (Label::Success, ScoreKind::Success)
    );
    if !fits || j.file.threshold != task.score_kind().threshold() {
        return Err(mismatch(format!(
            "estimates {} with success above {}, the task scores {}",
            j.file.label.array(),
            j.file.threshold,
            task.score_kind().describe()
        )));
    }
    Ok(j)
}

/// The model folders a run depends on, fingerprinted: the world model (when the run
/// uses one, with its folder) and its autoencoder, and every policy checkpoint.
///
/// # Errors
/// [`RunError::Fingerprint`]: a folder that cannot be read, naming it.
pub fn model_inputs(
    wm: Option<(&Path, &WorldModel)>,
    dirs: &[PathBuf],
) -> Result<Vec<Fingerprinted>, RunError> {
    let mut out = Vec::new();
    if let Some((wm_dir, wm)) = wm {
        out.push(("world_model".to_string(), wm_dir.to_path_buf()));
        if let Some(ae) = &wm.cfg.autoencoder {
            out.push(("autoencoder".to_string(), wm_dir.join(ae)));
        }
    }
    out.extend(dirs.iter().map(|d| (format!("policy {}", checkpoint_name(d)), d.clone())));
    out.into_iter()
        .map(|(k, d)| {
            let f = harness::fingerprint::folder(&d)?;
            Ok((k, d, f))
        })
        .collect()
}

/// The scenario file a run reads, fingerprinted (`scenario`, its path, the SHA-256 of
/// its bytes), so that `--resume` and `merge` refuse rows of a changed scene; none for a
/// built-in scenario given by name.
///
/// # Errors
/// [`RunError::Fingerprint`]: a scenario file that cannot be read.
pub fn scenario_input(scenario: &str) -> Result<Option<Fingerprinted>, RunError> {
    let path = Path::new(scenario);
    if !path.is_file() {
        return Ok(None);
    }
    let f = harness::fingerprint::file(path)?;
    Ok(Some(("scenario".to_string(), path.to_path_buf(), f)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scenario_file_is_fingerprinted_and_a_name_is_not() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("scene.toml");
        std::fs::write(&file, "x = 1\n").unwrap();
        let (name, path, sha) = scenario_input(file.to_str().unwrap()).unwrap().unwrap();
        assert_eq!((name.as_str(), path), ("scenario", file.clone()));
        assert!(sha.starts_with("sha256:"), "{sha}");
        assert!(scenario_input("lift").unwrap().is_none());
    }

    #[test]
    fn a_model_folder_that_is_not_there_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("nowhere");
        let e = load_world_model(&missing, None, None, &Device::flex()).err().unwrap();
        assert!(e.to_string().contains("nowhere"), "{e}");
        let e = read_judge_folder(&missing, &Device::flex()).err().unwrap().to_string();
        assert!(e.starts_with("--judge ") && e.contains("nowhere"), "{e}");
    }
}
