//! The models a run reads (`rank`, `plan`, `simulate --replay-imagined`, `wm eval`),
//! loaded with the run's options applied and checked against its task, and their
//! content fingerprints, which `config.json` records so that `--resume` and `merge`
//! refuse rows of changed models.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::tensor::Device;
use harness::task::{ScoreKind, Task};
use judges::folder::{FrameJudge, Label};
use policies::dir::checkpoint_name;
use world_model::model::WorldModel;

use crate::error::RunError;

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
    FrameJudge::load(dir, device).map_err(RunError::JudgeFolder)
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

/// The content fingerprints of everything a run reads, by the names `config.json`
/// records them under: the world model (when the run uses one) and its autoencoder
/// (`world_model`, `autoencoder`), every policy checkpoint (`policy NAME`), the learned
/// judge (`judge`), the scenario file (`scenario`; none for a task given by name) and the
/// task's parameters as loaded (`scenario parameters`, [`harness::task::Task::parameters`]:
/// a task given by name renders and simulates as the binary's defaults say, which a later
/// version may change).
///
/// # Errors
/// [`RunError::Fingerprint`]: a folder or file that cannot be read, naming it.
pub fn fingerprints(
    wm: Option<(&Path, &WorldModel)>,
    policies: &[PathBuf],
    judge: Option<&Path>,
    scenario: &str,
    parameters: Option<&serde_json::Value>,
) -> Result<BTreeMap<String, String>, RunError> {
    let mut out = BTreeMap::new();
    if let Some((wm_dir, wm)) = wm {
        out.insert("world_model".to_string(), harness::fingerprint::folder(wm_dir)?);
        if let Some(ae) = &wm.cfg.autoencoder {
            out.insert("autoencoder".to_string(), harness::fingerprint::folder(&wm_dir.join(ae))?);
        }
    }
    for d in policies {
        out.insert(format!("policy {}", checkpoint_name(d)), harness::fingerprint::folder(d)?);
    }
    if let Some(dir) = judge {
        out.insert("judge".to_string(), harness::fingerprint::folder(dir)?);
    }
    if let Some(sha) = scenario_file(scenario)? {
        out.insert("scenario".to_string(), sha);
    }
    if let Some(p) = parameters {
        out.insert("scenario parameters".to_string(), harness::fingerprint::bytes(p.to_string().as_bytes()));
    }
    Ok(out)
}

/// The SHA-256 of the scenario file a run reads, so that `--resume` and `merge` refuse
/// rows of a changed scene; none for a built-in scenario given by name.
fn scenario_file(scenario: &str) -> Result<Option<String>, RunError> {
    let path = Path::new(scenario);
    if !path.is_file() {
        return Ok(None);
    }
    Ok(Some(harness::fingerprint::file(path)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scenario_file_is_fingerprinted_and_a_name_is_not() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("scene.toml");
        std::fs::write(&file, "x = 1\n").unwrap();
        let sha = scenario_file(file.to_str().unwrap()).unwrap().unwrap();
        assert!(sha.starts_with("sha256:"), "{sha}");
        assert!(scenario_file("lift").unwrap().is_none());
        // Everything else a run reads is named as config.json records it.
        let policy = dir.path().join("epoch-0007");
        std::fs::create_dir_all(&policy).unwrap();
        let all =
            fingerprints(None, std::slice::from_ref(&policy), Some(dir.path()), file.to_str().unwrap(), None);
        let names: Vec<String> = all.unwrap().into_keys().collect();
        assert_eq!(names, ["judge", "policy epoch-0007", "scenario"]);
        // A task's parameters, given by name or by file, are fingerprinted as loaded: two
        // renderings of the same named task differ.
        let lift = |samples: u32| serde_json::json!({"visual": {"samples": samples}});
        let print = |p: &serde_json::Value| fingerprints(None, &[], None, "lift", Some(p)).unwrap();
        let (a, b) = (print(&lift(0)), print(&lift(4)));
        assert_eq!(a.keys().collect::<Vec<_>>(), ["scenario parameters"]);
        assert_ne!(a, b);
        assert_eq!(a, print(&lift(0)));
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
