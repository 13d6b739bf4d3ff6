//! Parameter names of Chi et al.'s diffusion-policy network as PyTorch checkpoints spell them,
//! mapped to evalharness's paths ([`crate::imported_policy::ImportedNet`]): torchvision's
//! ResNet-18 basic blocks and diffusion_policy's `ConditionalUnet1D`. One table for every
//! importer of that network: GPC's checkpoints ([`crate::import_gpc`]) and LeRobot's
//! ([`crate::import_lerobot`]) differ only in the names of a residual block's two
//! convolutions and of the resampling convolution, which [`UnetNames`] gives.
//!
//! Each function returns the path and whether the tensor is a Linear weight (stored
//! transposed in burn), or `None` for a name with no place.

use nn::ImportError;

/// A GroupNorm or BatchNorm parameter's burn name (`weight` → `gamma`, `bias` → `beta`).
pub(crate) fn norm(path: &str) -> String {
    path.replace(".weight", ".gamma").replace(".bias", ".beta")
}

/// A ResNet basic block's parameter `rest` (`conv1.weight`, `bn2.bias`, `downsample.0.weight`,
/// ...) under evalharness's block `o`.
pub(crate) fn resnet_block(o: &str, rest: &str) -> Option<(String, bool)> {
    let (sub, p) = rest.rsplit_once('.')?;
    Some(match sub {
        "conv1" => (format!("{o}.c1.conv.{p}"), false),
        "bn1" => (norm(&format!("{o}.c1.norm.{p}")), false),
        "conv2" => (format!("{o}.c2.conv.{p}"), false),
        "bn2" => (norm(&format!("{o}.c2.norm.{p}")), false),
        "downsample.0" => (format!("{o}.down.conv.{p}"), false),
        "downsample.1" => (norm(&format!("{o}.down.norm.{p}")), false),
        _ => return None,
    })
}

/// A parameter of torchvision's ResNet-18 kept as a `Sequential` of its children without the
/// pool and classifier (`0` conv1, `1` bn1, `4`–`7` layer1–4; LeRobot's `backbone.*`,
/// robomimic's `backbone.nets.*`), `r` being its name inside the `Sequential`.
pub(crate) fn resnet_children(r: &str) -> Option<(String, bool)> {
    if let Some(p) = r.strip_prefix("0.") {
        return Some((format!("encoder.stem.conv.{p}"), false));
    }
    if let Some(p) = r.strip_prefix("1.") {
        return Some((norm(&format!("encoder.stem.norm.{p}")), false));
    }
    let (layer, rest) = r.split_once('.')?;
    let (b, rest) = rest.split_once('.')?;
    let block =
        2 * layer.parse::<usize>().ok()?.checked_sub(4).filter(|l| *l < 4)? + b.parse::<usize>().ok()?;
    resnet_block(&format!("encoder.blocks.{block}"), rest)
}

/// The sizes of a `ConditionalUnet1D` read from its parameters' shapes (`shapes` by name
/// inside the U-Net module, `blocks.0` naming a residual block's first convolution).
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct UnetSizes {
    /// Channels per level.
    pub dims: Vec<usize>,
    /// Action width (the input's channels).
    pub action: usize,
    /// 1-D kernel size.
    pub kernel: usize,
    /// Step embedding.
    pub step_embed: usize,
    /// Global conditioning width (FiLM's input less the step embedding).
    pub cond: usize,
}

/// Reads [`UnetSizes`] from `shapes` (names inside the U-Net module, found in `path` under the
/// shown prefix `shown`).
///
/// # Errors
/// [`ImportError::Layout`] naming `path` and the U-Net's keys: the first name missing, or why
/// the shapes do not make a U-Net.
pub(crate) fn unet_sizes(
    shapes: &std::collections::BTreeMap<String, Vec<usize>>,
    first_conv: &str,
    path: &std::path::Path,
    shown: &str,
) -> Result<UnetSizes, ImportError> {
    let bad = |m: String| ImportError::Layout { path: path.into(), what: format!("`{shown}*`: {m}") };
    let mut dims = Vec::new();
    let (mut action, mut kernel) = (0, 0);
    while let Some(w) = shapes.get(&format!("down_modules.{}.0.{first_conv}.block.0.weight", dims.len())) {
        if w.len() != 3 {
            return Err(bad(format!(
                "down_modules.{}.0.{first_conv}.block.0.weight has shape {w:?}",
                dims.len()
            )));
        }
        if dims.is_empty() {
            (action, kernel) = (w[1], w[2]);
        }
        dims.push(w[0]);
    }
    if dims.is_empty() {
        return Err(bad(format!("missing down_modules.0.0.{first_conv}.block.0.weight")));
    }
    let get = |k: &str| {
        shapes.get(k).filter(|s| s.len() == 2).ok_or_else(|| bad(format!("missing {k} (or not 2-D)")))
    };
    let e = get("diffusion_step_encoder.1.weight")?[1];
    let film = get("down_modules.0.0.cond_encoder.1.weight")?[1];
    let cond = film
        .checked_sub(e)
        .ok_or_else(|| bad(format!("FiLM input {film} narrower than the step embedding {e}")))?;
    Ok(UnetSizes { dims, action, kernel, step_embed: e, cond })
}

/// How a checkpoint names the parts that differ between diffusion_policy's versions.
pub(crate) struct UnetNames {
    /// A residual block's two convolutions: `["blocks.0", "blocks.1"]` (diffusion_policy, GPC)
    /// or `["conv1", "conv2"]` (LeRobot).
    pub convs: [&'static str; 2],
    /// What precedes a resampling convolution's `weight` and `bias`: `conv.` (GPC) or nothing
    /// (LeRobot).
    pub resample: &'static str,
}

/// A `ConditionalUnet1D` parameter `r` (its name inside the U-Net module).
pub(crate) fn cond_unet(r: &str, names: &UnetNames) -> Option<(String, bool)> {
    let block = |o: &str, rest: &str| -> Option<(String, bool)> {
        let (sub, p) = rest.rsplit_once('.')?;
        for (i, c) in names.convs.iter().enumerate() {
            if sub == format!("{c}.block.0") {
                return Some((format!("{o}.b{i}.conv.{p}"), false));
            }
            if sub == format!("{c}.block.1") {
                return Some((norm(&format!("{o}.b{i}.norm.{p}")), false));
            }
        }
        match sub {
            "cond_encoder.1" => Some((format!("{o}.film.{p}"), p == "weight")),
            "residual_conv" => Some((format!("{o}.skip.{p}"), false)),
            _ => None,
        }
    };
    for (from, to) in
        [("diffusion_step_encoder.1.", "unet.step1."), ("diffusion_step_encoder.3.", "unet.step2.")]
    {
        if let Some(p) = r.strip_prefix(from) {
            return Some((format!("{to}{p}"), p == "weight"));
        }
    }
    if let Some(p) = r.strip_prefix("final_conv.0.block.0.") {
        return Some((format!("unet.final_block.conv.{p}"), false));
    }
    if let Some(p) = r.strip_prefix("final_conv.0.block.1.") {
        return Some((norm(&format!("unet.final_block.norm.{p}")), false));
    }
    if let Some(p) = r.strip_prefix("final_conv.1.") {
        return Some((format!("unet.final_conv.{p}"), false));
    }
    if let Some(rest) = r.strip_prefix("mid_modules.") {
        let (j, rest) = rest.split_once('.')?;
        return block(&format!("unet.mids.{j}"), rest);
    }
    for (theirs, ours, resample) in [("down_modules.", "downs", "down"), ("up_modules.", "ups", "up")] {
        if let Some(rest) = r.strip_prefix(theirs) {
            let (i, rest) = rest.split_once('.')?;
            let (j, rest) = rest.split_once('.')?;
            let o = format!("unet.{ours}.{i}");
            return match j {
                "0" | "1" => block(&format!("{o}.r{j}"), rest),
                "2" => rest.strip_prefix(names.resample).map(|p| (format!("{o}.{resample}.{p}"), false)),
                _ => None,
            };
        }
    }
    None
}
