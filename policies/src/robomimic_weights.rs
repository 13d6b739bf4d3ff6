//! The weights of a robomimic diffusion policy ([`crate::import_robomimic`]): the parameter
//! names a checkpoint of given sizes holds, where each lands in evalharness's networks, and
//! every tensor read, checked (shapes, the duplicated encoder copies, the spatial softmax's
//! keypoint grid) and placed.

use std::collections::BTreeMap;
use std::path::Path;

use burn::tensor::TensorData;
use nn::ImportError;
use nn::import::place::transpose;
use nn::import::tensors::Source;

use crate::import_gpc::official_names;
use crate::import_keys::{UnetNames, cond_unet, resnet_children};

/// Where a robomimic checkpoint keeps the image encoder's parameters (then the camera key).
pub(crate) const ENCODER: &str = "policy.obs_encoder.nets.obs.obs_nets.";
/// Where it keeps the noise-prediction U-Net's.
pub(crate) const UNET: &str = "policy.noise_pred_net.";

/// A checkpoint whose contents do not have the layout the importer reads.
pub(crate) fn layout(path: &Path, what: String) -> ImportError {
    ImportError::Layout { path: path.into(), what }
}

/// The parameters a robomimic checkpoint of these sizes names (each backbone and pool tensor
/// once, under `backbone.` and `pool.`): GPC's official list ([`official_names`], the same
/// torchvision ResNet and `ConditionalUnet1D`) renamed, and the pool's and Linear's.
pub(crate) fn expected_names(enc: &str, dims: &[usize], action: usize) -> Vec<String> {
    let mut v: Vec<String> = official_names(dims, action)
        .into_iter()
        .filter_map(|n| {
            if let Some(r) = n.strip_prefix("invariant.") {
                return Some(format!("{UNET}{r}"));
            }
            let r = n.strip_prefix("vision_encoder.")?;
            let r = match r.strip_prefix("layer") {
                Some(l) => {
                    let (stage, rest) = l.split_once('.')?;
                    format!("{}.{rest}", stage.parse::<usize>().ok()? + 3)
                }
                None => r.replacen("conv1.", "0.", 1).replacen("bn1.", "1.", 1),
            };
            Some(format!("{enc}backbone.nets.{r}"))
        })
        .collect();
    v.extend(
        ["pool.nets.weight", "pool.nets.bias", "nets.3.weight", "nets.3.bias"].map(|k| format!("{enc}{k}")),
    );
    v
}

/// evalharness's path of a robomimic weight `key` whose camera encoder is under `enc`, and
/// whether it is a Linear weight (transposed); `None` for the copies, buffers and any key with
/// no place.
pub(crate) fn burn_path(enc: &str, key: &str) -> Option<(String, bool)> {
    match key.strip_prefix(enc) {
        Some(r) => r
            .strip_prefix("backbone.nets.")
            .and_then(resnet_children)
            .or_else(|| r.strip_prefix("pool.nets.").map(|p| (format!("head.nets.{p}"), false)))
            .or_else(|| r.strip_prefix("nets.3.").map(|p| (format!("head.out.{p}"), p == "weight"))),
        None => key
            .strip_prefix(UNET)
            .and_then(|r| cond_unet(r, &UnetNames { convs: ["blocks.0", "blocks.1"], resample: "conv." })),
    }
}

/// Every tensor of `src` mapped onto the networks' parameters (`ours`, path → shape), checked.
pub(crate) fn weights_of(
    src: &Source,
    enc: &str,
    ours: &BTreeMap<String, Vec<usize>>,
) -> Result<(BTreeMap<String, TensorData>, usize), ImportError> {
    let path = src.path();
    let s = src.shapes();
    let f32s = |k: &str| src.f32s(k, &s[k]);
    let temperature = match s.get(&format!("{enc}pool.temperature")) {
        Some(_) => f32s(&format!("{enc}pool.temperature"))?,
        None => vec![1.0],
    };
    let t = match temperature.as_slice() {
        &[t] if t > 0.0 => t,
        other => {
            return Err(layout(
                path,
                format!(
                    "`{}` is {other:?}, not one positive value",
                    src.shown(&format!("{enc}pool.temperature"))
                ),
            ));
        }
    };
    let (mut values, mut unexpected) = (BTreeMap::new(), Vec::new());
    // The backbone's and pool's values as read, for their copies to be checked against; and
    // the copies (`nets.0.*`, `nets.1.*`) with the original each must equal.
    let (mut originals, mut copies) = (BTreeMap::new(), Vec::new());
    for (key, theirs) in &s {
        let local = key.strip_prefix(enc);
        // Copies robomimic keeps of the backbone and the pool: equal to what they copy.
        let original = local.and_then(|r| {
            r.strip_prefix("nets.0.")
                .map(|p| format!("{enc}backbone.{p}"))
                .or_else(|| r.strip_prefix("nets.1.").map(|p| format!("{enc}pool.{p}")))
        });
        if let Some(orig) = original {
            copies.push((key, orig));
            continue;
        }
        match local {
            Some("pool.temperature") => {
                originals.insert(key.clone(), temperature.clone());
                continue;
            }
            Some(grid @ ("pool.pos_x" | "pool.pos_y")) => {
                let v = f32s(key)?;
                check_grid(&v, grid == "pool.pos_x", path, &src.shown(key))?;
                originals.insert(key.clone(), v);
                continue;
            }
            _ => {}
        }
        let Some((to, linear)) = burn_path(enc, key).filter(|(to, _)| ours.contains_key(to)) else {
            unexpected.push(src.shown(key));
            continue;
        };
        let want = &ours[&to];
        let expect = if linear { vec![want[1], want[0]] } else { want.clone() };
        let mut v = src.f32s(key, &expect)?;
        if local.is_some_and(|r| r.starts_with("backbone.") || r.starts_with("pool.")) {
            originals.insert(key.clone(), v.clone());
        }
        if linear {
            v = transpose(&v, theirs[1], theirs[0]);
        }
        if to.starts_with("head.nets.") {
            // softmax(f / T) with f = W x + b is softmax((W / T) x + b / T).
            v.iter_mut().for_each(|x| *x /= t);
        }
        values.insert(to, TensorData::new(v, want.clone()));
    }
    for (key, orig) in copies {
        let v = f32s(key)?;
        if originals.get(&orig) != Some(&v) {
            return Err(layout(
                path,
                format!("`{}` is not a copy of `{}`", src.shown(key), src.shown(&orig)),
            ));
        }
    }
    if !unexpected.is_empty() {
        return Err(ImportError::Unexpected { path: path.into(), keys: unexpected });
    }
    if let Some(missing) = ours.keys().find(|p| !values.contains_key(*p)) {
        return Err(ImportError::Missing { path: path.into(), key: format!("the weights of `{missing}`") });
    }
    let n = values.len();
    Ok((values, n))
}

/// Checks a SpatialSoftmax grid buffer (`[1, h·w]`, a square map; key `shown` of `path`):
/// robomimic's `meshgrid(linspace(-1, 1, w), linspace(-1, 1, h))`, x varying along a row.
///
/// # Errors
/// [`ImportError::Layout`] naming the file and key: not a square map, or another grid.
pub(crate) fn check_grid(v: &[f32], is_x: bool, path: &Path, shown: &str) -> Result<(), ImportError> {
    let bad = |m: String| ImportError::Layout { path: path.into(), what: format!("`{shown}`: {m}") };
    let side = (v.len() as f64).sqrt().round() as usize;
    if side * side != v.len() || side == 0 {
        return Err(bad(format!("{} positions are not a square map", v.len())));
    }
    let lin = |i: usize| if side > 1 { -1.0 + 2.0 * i as f32 / (side - 1) as f32 } else { 0.0 };
    for (i, &got) in v.iter().enumerate() {
        let want = if is_x { lin(i % side) } else { lin(i / side) };
        if (got - want).abs() > 1e-6 {
            return Err(bad(format!("position {i} is {got}, robomimic's grid has {want}")));
        }
    }
    Ok(())
}
