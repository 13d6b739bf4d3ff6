//! Parameter names of Chi et al.'s diffusion-policy network as PyTorch checkpoints spell them,
//! mapped to evalharness's paths ([`crate::imported_policy::ImportedNet`]): torchvision's
//! ResNet-18 basic blocks and diffusion_policy's `ConditionalUnet1D`. One table for every
//! importer of that network: GPC's checkpoints ([`crate::import_gpc`]) and LeRobot's
//! ([`crate::import_lerobot`]) differ only in the names of a residual block's two
//! convolutions and of the resampling convolution, which [`UnetNames`] gives.
//!
//! Each function returns the path and whether the tensor is a Linear weight (stored
//! transposed in burn), or `None` for a name with no place.

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
