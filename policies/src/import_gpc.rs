//! DriftWorld/GPC's Push-T diffusion-policy checkpoints (`ckpt-ep{N}.pth`) as `gpc-diffusion`
//! policies.
//!
//! The file is `torch.save({step, model, ema, optimizer, scheduler, cfg})`: `model` the state
//! dict of `{vision_encoder, invariant}` (a ResNet-18 with GroupNorm, diffusion_policy's
//! `ConditionalUnet1D`), `ema` diffusers' EMA state whose `shadow_params` is a **list** of the
//! same parameters in `parameters()` order, which inference uses. The reader loses the pickle's
//! dict order, so the order is rebuilt here from the architecture ([`official_names`], checked
//! against the official module's own list by a test) and each EMA tensor must have the shape of
//! the model tensor of its place. `cfg` (a pickled OmegaConf object) is not read. The sizes are
//! read from the shapes; every key is mapped by [`burn_path`]; anything missing, unexpected,
//! mis-shaped, not float32 or not finite is refused naming the key.
//!
//! GPC's "official" layout (`use_official: True`) is a folder instead: `vision_encoder.pth` and
//! `invariant.pth`, plain state dicts of the training weights, and `ema_nets.pth`, the EMA's
//! state with the same `shadow_params` list; the same checks apply ([`FOLDER_FILES`]).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use burn::tensor::{Device, TensorData};
use nn::ImportError;
use nn::import::place::{place_all, shapes, transpose};
use nn::import::tensors::{Source, top_level_int};

use crate::import_keys::{UnetNames, UnetSizes, cond_unet, norm, resnet_block, unet_sizes};
use crate::imported_policy::{ImportedConfig, ImportedNet, Pool, Sampler};
use crate::net::NetConfig;
use crate::resnet_gn::BackboneNorm;

/// Which copy of the weights to import.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GpcWeights {
    /// `ema.shadow_params` (what GPC's evaluation runs).
    Ema,
    /// `model` (the raw training weights).
    Model,
}

/// An imported policy: its networks, config and what was read.
pub struct ImportedPolicy {
    /// The networks.
    pub net: ImportedNet,
    /// Their sizes.
    pub cfg: ImportedConfig,
    /// The training step (the file's `step`), if it has one.
    pub step: Option<i64>,
    /// Parameters read.
    pub tensors: usize,
}

/// A conditional residual block's parameters, in registration order, and whether it has a
/// 1×1 skip convolution (`cin != cout`).
fn cond_res(prefix: &str, skip: bool) -> Vec<String> {
    let mut v: Vec<String> =
        ["blocks.0.block.0", "blocks.0.block.1", "blocks.1.block.0", "blocks.1.block.1", "cond_encoder.1"]
            .iter()
            .flat_map(|m| [format!("{prefix}.{m}.weight"), format!("{prefix}.{m}.bias")])
            .collect();
    if skip {
        v.extend([format!("{prefix}.residual_conv.weight"), format!("{prefix}.residual_conv.bias")]);
    }
    v
}

/// The official parameter names in `parameters()` order (the order of `ema.shadow_params`),
/// for U-Net levels of `dims` channels after an `action`-wide input.
pub fn official_names(dims: &[usize], action: usize) -> Vec<String> {
    let mut v = vec!["vision_encoder.conv1.weight".into()];
    v.extend(["vision_encoder.bn1.weight".into(), "vision_encoder.bn1.bias".into()]);
    for s in 1..=4 {
        for i in 0..2 {
            let k = format!("vision_encoder.layer{s}.{i}");
            for p in ["conv1.weight", "bn1.weight", "bn1.bias", "conv2.weight", "bn2.weight", "bn2.bias"] {
                v.push(format!("{k}.{p}"));
            }
            if s > 1 && i == 0 {
                v.extend(
                    [".downsample.0.weight", ".downsample.1.weight", ".downsample.1.bias"]
                        .map(|p| format!("{k}{p}")),
                );
            }
        }
    }
    let u = "invariant";
    for j in 0..2 {
        v.extend(cond_res(&format!("{u}.mid_modules.{j}"), false));
    }
    for l in [1, 3] {
        v.extend(["weight", "bias"].map(|p| format!("{u}.diffusion_step_encoder.{l}.{p}")));
    }
    let ins: Vec<usize> = std::iter::once(action).chain(dims.iter().copied()).collect();
    let pairs: Vec<(usize, usize)> = ins.windows(2).map(|w| (w[0], w[1])).collect();
    for (i, &(a, b)) in pairs[1..].iter().rev().enumerate() {
        v.extend(cond_res(&format!("{u}.up_modules.{i}.0"), 2 * b != a));
        v.extend(cond_res(&format!("{u}.up_modules.{i}.1"), false));
        v.extend(["weight", "bias"].map(|p| format!("{u}.up_modules.{i}.2.conv.{p}")));
    }
    for (i, &(a, b)) in pairs.iter().enumerate() {
        v.extend(cond_res(&format!("{u}.down_modules.{i}.0"), a != b));
        v.extend(cond_res(&format!("{u}.down_modules.{i}.1"), false));
        if i + 1 < pairs.len() {
            v.extend(["weight", "bias"].map(|p| format!("{u}.down_modules.{i}.2.conv.{p}")));
        }
    }
    for m in ["final_conv.0.block.0", "final_conv.0.block.1", "final_conv.1"] {
        v.extend(["weight", "bias"].map(|p| format!("{u}.{m}.{p}")));
    }
    v
}

/// evalharness's path of an official parameter, and whether it is a Linear weight (transposed).
pub fn burn_path(name: &str) -> Option<(String, bool)> {
    if let Some(r) = name.strip_prefix("vision_encoder.") {
        if let Some(p) = r.strip_prefix("conv1.") {
            return Some((format!("encoder.stem.conv.{p}"), false));
        }
        if let Some(p) = r.strip_prefix("bn1.") {
            return Some((norm(&format!("encoder.stem.norm.{p}")), false));
        }
        let (stage, rest) = r.strip_prefix("layer")?.split_once('.')?;
        let (i, rest) = rest.split_once('.')?;
        let b = 2 * (stage.parse::<usize>().ok()?.checked_sub(1)?) + i.parse::<usize>().ok()?;
        return resnet_block(&format!("encoder.blocks.{b}"), rest);
    }
    cond_unet(
        name.strip_prefix("invariant.")?,
        &UnetNames { convs: ["blocks.0", "blocks.1"], resample: "conv." },
    )
}

/// A GPC policy's training weights by official name (`vision_encoder.*`, `invariant.*`), from
/// either layout GPC writes.
enum Model {
    /// `ckpt-epN.pth`'s `model` entry.
    File(Source),
    /// The "official" folder (`use_official: True`): `vision_encoder.pth` and `invariant.pth`,
    /// plain state dicts of each network.
    Folder { dir: PathBuf, parts: [(&'static str, Source); 2] },
}

/// The files of GPC's "official" folder layout.
pub const FOLDER_FILES: [&str; 3] = ["vision_encoder.pth", "invariant.pth", "ema_nets.pth"];

impl Model {
    fn open(path: &Path) -> Result<Self, ImportError> {
        if !path.is_dir() {
            return Ok(Self::File(Source::open(path, Some("model"), "")?));
        }
        if let Some(f) = FOLDER_FILES.iter().find(|f| !path.join(f).is_file()) {
            return Err(ImportError::Missing {
                path: path.into(),
                key: format!("the file {f} (GPC's folder layout)"),
            });
        }
        let part = |name: &'static str| -> Result<(&'static str, Source), ImportError> {
            Ok((name, Source::open(&path.join(format!("{name}.pth")), None, "")?))
        };
        Ok(Self::Folder { dir: path.into(), parts: [part("vision_encoder")?, part("invariant")?] })
    }

    /// The EMA's `shadow_params` and the file's step entry.
    fn ema_and_step(&self, path: &Path) -> (PathBuf, Option<&'static str>, &'static str) {
        match self {
            Self::File(_) => (path.into(), Some("ema"), "step"),
            Self::Folder { dir, .. } => (dir.join("ema_nets.pth"), None, "optimization_step"),
        }
    }

    /// The part holding official name `name`, and the name inside it.
    fn part<'a>(&'a self, name: &'a str) -> Option<(&'a Source, &'a str)> {
        match self {
            Self::File(src) => Some((src, name)),
            Self::Folder { parts, .. } => {
                parts.iter().find_map(|(p, src)| Some((src, name.strip_prefix(p)?.strip_prefix('.')?)))
            }
        }
    }

    fn shapes(&self) -> BTreeMap<String, Vec<usize>> {
        match self {
            Self::File(src) => src.shapes(),
            Self::Folder { parts, .. } => parts
                .iter()
                .flat_map(|(p, src)| src.shapes().into_iter().map(move |(k, v)| (format!("{p}.{k}"), v)))
                .collect(),
        }
    }

    fn path(&self) -> &Path {
        match self {
            Self::File(src) => src.path(),
            Self::Folder { dir, .. } => dir,
        }
    }

    /// How the files name `name`, for messages.
    fn shown(&self, name: &str) -> String {
        match (self, self.part(name)) {
            (Self::File(src), _) => src.shown(name),
            (Self::Folder { .. }, Some((src, inner))) => format!("{}: {inner}", src.path().display()),
            (Self::Folder { dir, .. }, None) => format!("{}: {name}", dir.display()),
        }
    }

    fn f32s(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>, ImportError> {
        let (src, inner) = self
            .part(name)
            .ok_or_else(|| ImportError::Missing { path: self.path().into(), key: name.to_string() })?;
        src.f32s(inner, shape)
    }
}

/// The sizes a checkpoint's shapes give (the ResNet base, the U-Net's levels, kernel and
/// step embedding, the action and proprioception widths), for `obs_horizon` frames.
fn config_from(src: &Model, image_size: usize, obs_horizon: usize) -> Result<ImportedConfig, ImportError> {
    let s = src.shapes();
    let missing = |k: &str| ImportError::Missing { path: src.path().into(), key: src.shown(k) };
    let get = |k: &str| s.get(k).cloned().ok_or_else(|| missing(k));
    let layout = |what: String| ImportError::Layout { path: src.path().into(), what };
    let base = match get("vision_encoder.conv1.weight")?.as_slice() {
        &[b, 3, 7, 7] if b > 0 && b % 16 == 0 => b,
        other => {
            return Err(layout(format!(
                "key `vision_encoder.conv1.weight` has shape {other:?}, expected [64, 3, 7, 7]"
            )));
        }
    };
    let unet: BTreeMap<String, Vec<usize>> =
        s.iter().filter_map(|(k, v)| Some((k.strip_prefix("invariant.")?.to_string(), v.clone()))).collect();
    let UnetSizes { dims, action, kernel, step_embed: e, cond } =
        unet_sizes(&unet, "blocks.0", src.path(), &src.shown("invariant."))?;
    let features = 8 * base;
    let proprio =
        (cond / obs_horizon.max(1)).checked_sub(features).filter(|_| cond % obs_horizon.max(1) == 0);
    let Some(proprio) = proprio else {
        return Err(layout(format!(
            "conditioning of {cond} entries is not {obs_horizon} frames of {features} features plus a position"
        )));
    };
    let net = NetConfig {
        image_size,
        encoder_width: base,
        feature_dim: features,
        down_dims: dims,
        kernel,
        step_embed: e,
        obs_horizon,
        action_dim: action,
        proprio_dim: Some(proprio),
    };
    Ok(ImportedConfig {
        resnet_base: base,
        backbone_norm: BackboneNorm::Group,
        pool: Pool::Average,
        input_size: None,
        antialias: false,
        crop: None,
        image_norm: None,
        position_first: false,
        robot_keys: Vec::new(),
        inference_steps: None,
        sampler: Sampler::Ddpm,
        prediction: crate::imported_policy::Prediction::Epsilon,
        net,
        horizon: 16,
        action_horizon: 8,
        train_steps: 100,
    })
}

/// Imports a GPC policy checkpoint.
///
/// # Errors
/// [`ImportError`] naming the file and key for anything missing, unexpected, mis-shaped,
/// non-float32 or non-finite, an EMA list of another length than the parameters, or sizes
/// that do not make GPC's networks.
pub fn import(
    path: &Path,
    weights: GpcWeights,
    image_size: usize,
    device: &Device,
) -> Result<ImportedPolicy, ImportError> {
    let model = Model::open(path)?;
    let cfg = config_from(&model, image_size, 2)?;
    let names = official_names(&cfg.net.down_dims, cfg.net.action_dim);
    let shapes_of = model.shapes();
    // Every key of `model` is one of the official names, and every name is there.
    let known: BTreeSet<&str> = names.iter().map(String::as_str).collect();
    let unexpected: Vec<String> =
        shapes_of.keys().filter(|k| !known.contains(k.as_str())).map(|k| model.shown(k)).collect();
    if !unexpected.is_empty() {
        return Err(ImportError::Unexpected { path: path.into(), keys: unexpected });
    }
    if let Some(n) = names.iter().find(|n| !shapes_of.contains_key(*n)) {
        return Err(ImportError::Missing { path: path.into(), key: model.shown(n) });
    }
    let (ema_file, ema_top, step_key) = model.ema_and_step(path);
    let ema = match weights {
        GpcWeights::Ema => Some(Source::open(&ema_file, ema_top, "shadow_params.")?),
        GpcWeights::Model => None,
    };
    if let Some(ema) = &ema {
        let count = ema.names().count();
        if count != names.len() || ema.names().any(|n| n.parse::<usize>().map_or(true, |i| i >= names.len()))
        {
            return Err(ImportError::Layout {
                path: path.into(),
                what: format!(
                    "`ema.shadow_params` holds {count} tensors, the networks have {} parameters",
                    names.len()
                ),
            });
        }
    }
    let net = ImportedNet::new(&cfg, device);
    let ours = shapes(&net);
    let mut values = BTreeMap::new();
    for (i, name) in names.iter().enumerate() {
        let theirs = &shapes_of[name];
        let (to, linear) = burn_path(name).ok_or_else(|| ImportError::Layout {
            path: path.into(),
            what: format!("no place for key `{}`", model.shown(name)),
        })?;
        let want = ours.get(&to).ok_or_else(|| ImportError::Layout {
            path: path.into(),
            what: format!("key `{}` maps to `{to}`, which the networks lack", model.shown(name)),
        })?;
        let v = match &ema {
            Some(e) => e.f32s(&i.to_string(), theirs).map_err(|err| match err {
                ImportError::Shape { path, key, found, expected } => ImportError::Layout {
                    path,
                    what: format!("`{key}` has shape {found:?}, but parameter {i} (`{name}`) has {expected:?}: the EMA list is not in the networks' order"),
                },
                other => other,
            })?,
            None => model.f32s(name, theirs)?,
        };
        let v = if linear { transpose(&v, theirs[1], theirs[0]) } else { v };
        if v.len() != want.iter().product::<usize>() {
            return Err(ImportError::Shape {
                path: path.into(),
                key: model.shown(name),
                found: theirs.clone(),
                expected: want.clone(),
            });
        }
        values.insert(to, TensorData::new(v, want.clone()));
    }
    let net = place_all(net, values, path)?;
    let tensors = names.len();
    Ok(ImportedPolicy { net, cfg, step: top_level_int(&ema_file, step_key), tensors })
}

#[cfg(test)]
#[path = "import_gpc_tests.rs"]
mod tests;
