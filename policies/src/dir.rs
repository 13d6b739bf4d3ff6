//! The policy directory format: a checkpoint folder's `policy.json` and weights, read and
//! written ([`crate::kinds::load_policy`] loads one by its kind).
//!
//! A checkpoint is a folder with `policy.json` — kind, config, normalisation
//! statistics, training epoch, provenance — and its weights (`model.bpk`).
//! A policy directory is either one checkpoint or a folder of them (hidden
//! sub-folders, such as a trainer's `.train/`, are skipped). Loading validates the
//! kind, the image size and the action dimension against what the scenario
//! provides, and every error names the checkpoint folder.

use std::path::{Path, PathBuf};

use burn::module::{Module, ModuleMapper, Param};
use burn::store::{ModuleRecord, RecordError};
use burn::tensor::{DType, Device, Tensor};

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::provenance::{Made, PolicyProvenance};

use crate::diffusion::{DiffusionConfig, DiffusionNet, Normalisation};

/// A problem with a policy checkpoint, naming its folder or file.
#[derive(Debug, thiserror::Error)]
#[error("policy {path}: {message}")]
pub struct PolicyLoadError {
    /// The checkpoint folder or file.
    pub path: PathBuf,
    /// What is wrong.
    pub message: String,
}

impl PolicyLoadError {
    /// An error about `path`.
    pub fn new(path: &Path, message: impl Into<String>) -> Self {
        Self { path: path.to_path_buf(), message: message.into() }
    }
}

/// A run file of a policy's training (its log, its state) that cannot be read or written.
impl From<harness::runfile::RunFileError> for PolicyLoadError {
    fn from(e: harness::runfile::RunFileError) -> Self {
        Self { path: e.path, message: e.message }
    }
}

/// `policy.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolicyFile {
    /// The policy kind (`diffusion`).
    pub kind: String,
    /// Training epoch of this checkpoint.
    pub epoch: u64,
    /// Optimizer steps of this checkpoint.
    pub step: u64,
    /// Kind-specific configuration.
    pub config: Value,
    /// Normalisation statistics.
    pub normalisation: Normalisation,
    /// How it was made (command, data, seed, commit).
    pub provenance: PolicyProvenance,
    /// Training loss at the checkpoint (absent for an imported one, which does not say).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub train_loss: Option<f64>,
    /// The task its demonstrations came from (`pusht`, `lift`, `can`): a checkpoint of
    /// one arm task reads and acts like one of the other, so only this tells them apart.
    /// Absent in checkpoints written before 2026-11-29, which are not checked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub task: Option<String>,
}

impl PolicyFile {
    /// The file of a diffusion-policy checkpoint.
    pub fn diffusion(
        cfg: &DiffusionConfig,
        norm: &Normalisation,
        epoch: u64,
        step: u64,
        provenance: &PolicyProvenance,
        train_loss: f64,
        task: Option<&str>,
    ) -> Self {
        Self {
            kind: "diffusion".into(),
            epoch,
            step,
            config: serde_json::to_value(cfg).unwrap_or(Value::Null),
            normalisation: norm.clone(),
            provenance: provenance.clone(),
            train_loss: Some(train_loss),
            task: task.map(str::to_owned),
        }
    }
}

struct ToF16;

impl ModuleMapper for ToF16 {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        param.map(|t| t.cast(DType::F16))
    }
}

/// Saves a module's weights in f16 (half the size; policies lose nothing measurable).
///
/// # Errors
/// burn's [`RecordError`] (the file cannot be written).
pub fn save_f16<M: Module>(module: &M, path: &Path) -> Result<(), RecordError> {
    module.clone().map(&mut ToF16).save_file(path)
}

/// Loads weights saved in any float precision into `module`'s dtype.
///
/// # Errors
/// burn's [`RecordError`] (a missing, truncated or mismatched file).
pub fn load_weights<M: Module>(module: M, path: &Path) -> Result<M, RecordError> {
    let record = ModuleRecord::load(path)?.cast_to_module_dtype();
    module.try_load_record(record)
}

/// Writes a checkpoint folder (`policy.json` + `model.bpk`, weights in f16).
///
/// # Errors
/// [`PolicyLoadError`] naming the file that could not be written.
pub fn write_policy(dir: &Path, file: &PolicyFile, net: &DiffusionNet) -> Result<(), PolicyLoadError> {
    write_policy_with(dir, file, |w| save_f16(net, w))
}

/// Writes an imported checkpoint folder (`policy.json` + `model.bpk`, weights in f32 as
/// they were trained: no rounding of someone else's weights).
///
/// # Errors
/// [`PolicyLoadError`] naming the file that could not be written.
pub fn write_policy_f32<M: Module>(dir: &Path, file: &PolicyFile, net: &M) -> Result<(), PolicyLoadError> {
    write_policy_with(dir, file, |w| net.clone().save_file(w))
}

fn write_policy_with(
    dir: &Path,
    file: &PolicyFile,
    save: impl FnOnce(&Path) -> Result<(), RecordError>,
) -> Result<(), PolicyLoadError> {
    std::fs::create_dir_all(dir).map_err(|e| PolicyLoadError::new(dir, e.to_string()))?;
    let weights = dir.join("model.bpk");
    save(&weights).map_err(|e| PolicyLoadError::new(&weights, e.to_string()))?;
    let json = dir.join("policy.json");
    let text = serde_json::to_string_pretty(file).unwrap_or_default();
    std::fs::write(&json, text + "\n").map_err(|e| PolicyLoadError::new(&json, e.to_string()))
}

/// What the scenario feeds a policy and accepts from it.
#[derive(Clone, Debug, PartialEq)]
pub struct Expectations {
    /// Frame side in pixels.
    pub image_size: usize,
    /// Entries of the proprioceptive vector.
    pub proprio_dim: usize,
    /// Each action entry's lower bound (its length is the action dimension).
    pub action_low: Vec<f32>,
    /// Each action entry's upper bound.
    pub action_high: Vec<f32>,
    /// The task's name: a checkpoint that records another task is refused.
    pub task: Option<String>,
    /// The robot-state keys the task gives ([`harness::task::ObservationSpec::robot`]).
    pub robot: Vec<harness::task::StateKey>,
}

impl Expectations {
    /// Push-T's: `image_size`² frames, the agent's 2-D position, targets in [0, 512]².
    pub fn pusht(image_size: usize) -> Self {
        Self {
            image_size,
            proprio_dim: 2,
            action_low: vec![0.0; 2],
            action_high: vec![512.0; 2],
            task: Some("pusht".into()),
            robot: Vec::new(),
        }
    }

    /// Entries per action.
    pub fn action_dim(&self) -> usize {
        self.action_low.len()
    }
}

/// A checkpoint's name: its folder's name (the whole path when it has none).
pub fn checkpoint_name(dir: &Path) -> String {
    dir.file_name().map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into_owned())
}

/// The `kind` of a checkpoint folder's `policy.json` (every kind's file has one; the rest of
/// the file depends on it), or `None` for a missing or unreadable file or a file without one.
pub fn policy_kind(dir: &Path) -> Option<String> {
    /// The one field every kind's `policy.json` shares.
    #[derive(Deserialize)]
    struct Kind {
        kind: String,
    }
    let text = std::fs::read_to_string(dir.join("policy.json")).ok()?;
    serde_json::from_str::<Kind>(&text).ok().map(|k| k.kind)
}

/// Reads a checkpoint folder's `policy.json`.
///
/// # Errors
/// [`PolicyLoadError`] naming the folder for a missing or malformed file.
pub fn read_policy_file(dir: &Path) -> Result<PolicyFile, PolicyLoadError> {
    read_policy_json(dir)
}

/// `dir/policy.json` read as `T`, naming the folder and file in any error.
fn read_policy_json<T: serde::de::DeserializeOwned>(dir: &Path) -> Result<T, PolicyLoadError> {
    let err = |m: String| PolicyLoadError::new(dir, m);
    let text =
        std::fs::read_to_string(dir.join("policy.json")).map_err(|e| err(format!("policy.json: {e}")))?;
    serde_json::from_str(&text).map_err(|e| err(format!("policy.json: {e}")))
}

/// What any policy folder's `policy.json` says of how the policy was made, whatever its
/// kind.
///
/// # Errors
/// [`PolicyLoadError`] naming the folder for a missing or malformed file.
pub fn read_made(dir: &Path) -> Result<Made, PolicyLoadError> {
    read_policy_json(dir)
}

/// The diffusion config of a checkpoint's `policy.json`, checked for a usable action horizon.
///
/// # Errors
/// [`PolicyLoadError`] naming the folder for another kind or an invalid config.
pub fn diffusion_config(dir: &Path, file: &PolicyFile) -> Result<DiffusionConfig, PolicyLoadError> {
    let err = |m: String| PolicyLoadError::new(dir, m);
    if file.kind != "diffusion" {
        return Err(err(format!("policy.json: kind \"{}\", expected \"diffusion\"", file.kind)));
    }
    let cfg: DiffusionConfig = serde_json::from_value(file.config.clone())
        .map_err(|e| err(format!("policy.json \"config\": {e}")))?;
    if cfg.action_horizon == 0 || cfg.action_horizon > cfg.max_action_horizon() {
        return Err(err(format!(
            "action horizon {} does not fit horizon {}",
            cfg.action_horizon, cfg.horizon
        )));
    }
    Ok(cfg)
}

/// A diffusion checkpoint's networks (`model.bpk`) built for `cfg` on `device`.
///
/// # Errors
/// [`PolicyLoadError`] naming the folder for weights that are missing, truncated or
/// do not match the config.
pub fn diffusion_weights(
    dir: &Path,
    cfg: &DiffusionConfig,
    device: &Device,
) -> Result<DiffusionNet, PolicyLoadError> {
    load_weights(DiffusionNet::new(cfg, device), &dir.join("model.bpk"))
        .map_err(|e| PolicyLoadError::new(dir, format!("model.bpk: {e}")))
}

/// The checkpoint folders of a policy directory: itself if it holds `policy.json`,
/// else its non-hidden sub-folders, sorted by name.
///
/// # Errors
/// [`PolicyLoadError`] if `dir` cannot be read or holds no checkpoint.
pub fn checkpoint_dirs(dir: &Path) -> Result<Vec<PathBuf>, PolicyLoadError> {
    if dir.join("policy.json").is_file() {
        return Ok(vec![dir.to_path_buf()]);
    }
    let rd = std::fs::read_dir(dir).map_err(|e| PolicyLoadError::new(dir, e.to_string()))?;
    let mut dirs: Vec<PathBuf> = rd
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.is_dir() && !p.file_name().is_some_and(|n| n.to_string_lossy().starts_with('.')))
        .collect();
    dirs.sort();
    if dirs.is_empty() {
        return Err(PolicyLoadError::new(dir, "no policy.json and no checkpoint sub-folders"));
    }
    // A policy's rows are keyed by its name as text: two folders whose names read the
    // same (non-UTF-8 bytes both decoded to U+FFFD) would pool their rows.
    for (i, a) in dirs.iter().enumerate() {
        if let Some(b) = dirs[i + 1..].iter().find(|b| checkpoint_name(b) == checkpoint_name(a)) {
            return Err(PolicyLoadError::new(
                dir,
                format!(
                    "checkpoints {:?} and {:?} have the same name as text ({}); rename one",
                    a.file_name().unwrap_or_default(),
                    b.file_name().unwrap_or_default(),
                    checkpoint_name(a)
                ),
            ));
        }
    }
    Ok(dirs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folders_whose_names_read_the_same_are_refused() {
        // At 92f9f2b folders named b"a\xff" and b"a\xfe" both became "a\u{fffd}" and
        // their rows were pooled as one policy.
        use std::os::unix::ffi::OsStrExt;
        let dir = std::env::temp_dir().join(format!("evalharness-names-{}", std::process::id()));
        for name in [&b"a\xff"[..], &b"a\xfe"[..]] {
            std::fs::create_dir_all(dir.join(std::ffi::OsStr::from_bytes(name))).unwrap();
        }
        let e = checkpoint_dirs(&dir).unwrap_err().to_string();
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(e.contains("same name as text"), "{e}");
    }

    #[test]
    fn f16_weights_round_trip() {
        let device = Device::flex();
        let cfg = DiffusionConfig {
            net: crate::net::NetConfig::new().with_encoder_width(8).with_down_dims(vec![16, 32]),
            ..DiffusionConfig::default()
        };
        let net = DiffusionNet::new(&cfg, &device);
        let path = std::env::temp_dir().join(format!("evalharness-f16-{}.bpk", std::process::id()));
        save_f16(&net, &path).unwrap();
        let back = load_weights(DiffusionNet::new(&cfg, &device), &path).unwrap();
        std::fs::remove_file(&path).unwrap();
        let x = Tensor::<4>::ones([1, 3, 96, 96], &device) * 0.3;
        let (a, b) = (net.encoder.forward(x.clone()), back.encoder.forward(x));
        let rel: f32 = ((a.clone() - b).abs().max() / a.abs().max()).into_scalar();
        // f16 has an 11-bit mantissa: relative weight error ≤ 2^-11 ≈ 4.9e-4.
        assert!(rel < 5e-3, "{rel}");
    }
}
