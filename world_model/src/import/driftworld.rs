//! The official DriftWorld code's world-model checkpoints (`torch.save({step, model, optimizer,
//! scheduler})`, `model` holding `inner_model.*` and its EMA copy `ema_model.*`) as an
//! evalharness pixel-space world model.
//!
//! The official U-Net is evalharness's [`UNet`] block for block (ADM layout, factorised 3-D
//! convolutions, FiLM from a per-frame action embedding, no timestep input), with two
//! differences the import settles:
//! - its attention GroupNorm runs per frame ([`UNetConfig::frame_attention_norm`]);
//! - its qkv rows are head-major (`[head][q, k, v][d]`), evalharness's q/k/v-major
//!   (`[q, k, v][head][d]`): [`permute_qkv`].
//!
//! PyTorch's Linear weights are `[out, in]`, burn's `[in, out]`; GroupNorm's weight and bias
//! are burn's gamma and beta; convolutions share the OIHW layout. The network's shape (width,
//! levels, blocks per level, attention levels, history, action size) is read from the file's
//! shapes ([`plan`]); what no tensor shows (future frames per pass, frame size, channels per
//! attention head, how actions are normalised) comes from a [`Preset`].

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use burn::tensor::{Device, TensorData};
use serde::{Deserialize, Serialize};

use crate::action::ActionScale;
use crate::model::WorldModelConfig;
use crate::unet::{UNet, UNetConfig};
use nn::ImportError;
use nn::import::place::{place_all, shapes as module_shapes, transpose};
use nn::import::tensors::{Source, top_level_int};

/// GroupNorm groups of the official code (`GroupNorm32`: 32 groups everywhere).
pub const GROUPS: usize = 32;

/// Which of the checkpoint's two copies to import.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Weights {
    /// `model.ema_model.*`, what the official sampler uses.
    Ema,
    /// `model.inner_model.*`, the trained weights before averaging.
    Inner,
}

impl Weights {
    fn prefix(self) -> &'static str {
        match self {
            Weights::Ema => "ema_model.",
            Weights::Inner => "inner_model.",
        }
    }
}

/// The facts of an official configuration that no tensor shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// Push-T: 4 future frames per pass, 96² frames, 2-D actions in world units 0..511.
    Pusht,
    /// robomimic Lift: 2 future frames, 96² frames, raw 7-D actions in [-1, 1].
    Lift,
    /// robomimic Can: as Lift.
    Can,
}

impl Preset {
    /// Future frames per U-Net pass.
    pub fn future(self) -> usize {
        match self {
            Preset::Pusht => 4,
            Preset::Lift | Preset::Can => 2,
        }
    }

    /// Channels per attention head (`num_head_channels`).
    pub fn head_dim(self) -> usize {
        8
    }

    /// The frames' side in pixels.
    pub fn image_size(self) -> usize {
        96
    }

    /// How actions map to [-1, 1].
    pub fn actions(self) -> ActionScale {
        match self {
            Preset::Pusht => ActionScale::pusht(),
            Preset::Lift | Preset::Can => ActionScale { low: vec![-1.0; 7], high: vec![1.0; 7] },
        }
    }
}

/// What an import read and from where (written to the model's `config.json` and
/// `provenance.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImportRecord {
    /// The source format (`driftworld`).
    pub format: String,
    /// The file, as given.
    pub source: PathBuf,
    /// Its SHA-256.
    pub sha256: String,
    /// The checkpoint's training step, when it records one.
    pub step: Option<i64>,
    /// Which copy was imported.
    pub weights: Weights,
    /// The preset that supplied what the file does not show.
    pub preset: Preset,
    /// Tensors imported.
    pub tensors: usize,
    /// Parameters imported.
    pub parameters: usize,
}

/// How one official tensor becomes one of ours.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transform {
    /// The same layout.
    Same,
    /// A Linear weight: `[out, in]` → `[in, out]`.
    Transpose,
    /// Attention qkv rows, head-major → q/k/v-major, with this many heads.
    Qkv {
        /// Heads.
        heads: usize,
    },
}

/// One official key and where it goes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Entry {
    /// The official key (without the `ema_model.` prefix).
    pub key: String,
    /// The path of the parameter in [`UNet`].
    pub ours: String,
    /// The conversion.
    pub transform: Transform,
}

/// The network a file's shapes describe, and the mapping of every key.
#[derive(Clone, Debug)]
pub struct Plan {
    /// The U-Net configuration (per-frame attention norms, 32 groups).
    pub unet: UNetConfig,
    /// Every official key, once.
    pub entries: Vec<Entry>,
}

/// The shape `key` has in `shapes`, or [`ImportError::Layout`]/[`ImportError::Missing`].
fn shape<'a>(
    shapes: &'a BTreeMap<String, Vec<usize>>,
    key: &str,
    path: &Path,
) -> Result<&'a [usize], ImportError> {
    shapes
        .get(key)
        .map(Vec::as_slice)
        .ok_or_else(|| ImportError::Missing { path: path.into(), key: key.into() })
}

/// Reads the network's configuration from the official keys' shapes and maps every key.
///
/// # Errors
/// [`ImportError::Missing`] for a key the layout needs, [`ImportError::Layout`] for shapes no
/// official network has.
pub fn plan(shapes: &BTreeMap<String, Vec<usize>>, preset: Preset, path: &Path) -> Result<Plan, ImportError> {
    let layout = |what: String| ImportError::Layout { path: path.into(), what };
    let conv_in = shape(shapes, "input_blocks.0.0.spatial_conv.weight", path)?;
    let conv_out = shape(shapes, "out.2.spatial_conv.weight", path)?;
    let act = shape(shapes, "action_embed.0.weight", path)?;
    let (&[mc, cin, _, _], &[fc, _, _, _], &[emb, action_dim]) = (conv_in, conv_out, act) else {
        return Err(layout("`input_blocks.0.0.spatial_conv.weight`, `out.2.spatial_conv.weight` or `action_embed.0.weight` has the wrong rank".into()));
    };
    if fc == 0 || cin % fc != 0 || cin / fc < 2 {
        return Err(layout(format!("`input_blocks.0.0` reads {cin} channels, not (history + 1) × {fc}")));
    }
    let history = cin / fc - 1;
    let block_count = |prefix: &str| {
        shapes
            .keys()
            .filter_map(|k| k.strip_prefix(prefix)?.split('.').next()?.parse::<usize>().ok())
            .max()
            .map_or(0, |m| m + 1)
    };
    let n_in = block_count("input_blocks.");
    let downs: Vec<usize> = (0..n_in)
        .filter(|i| shapes.contains_key(&format!("input_blocks.{i}.0.op.spatial_conv.weight")))
        .collect();
    let levels = downs.len() + 1;
    // input_blocks = conv_in + levels × res_blocks + (levels − 1) downsamplings.
    if n_in < 2 * levels || !(n_in - levels).is_multiple_of(levels) {
        return Err(layout(format!("{n_in} input blocks with {} downsamplings fit no U-Net", downs.len())));
    }
    let res_blocks = (n_in - levels) / levels;
    let first = |l: usize| 1 + l * (res_blocks + 1); // the first block of level l
    let mut channel_mult = Vec::with_capacity(levels);
    let mut attention_rates = Vec::new();
    for l in 0..levels {
        let key = format!("input_blocks.{}.0.in_layers.2.spatial_conv.weight", first(l));
        let co = shape(shapes, &key, path)?[0];
        if mc == 0 || co % mc != 0 {
            return Err(layout(format!("`{key}` has {co} output channels, not a multiple of {mc}")));
        }
        channel_mult.push(co / mc);
        if shapes.contains_key(&format!("input_blocks.{}.1.qkv.weight", first(l))) {
            attention_rates.push(1 << l);
        }
    }
    let unet = UNetConfig::new(fc, mc, channel_mult, attention_rates)
        .with_history(history)
        .with_res_blocks(res_blocks)
        .with_head_dim(preset.head_dim())
        .with_groups(GROUPS)
        .with_action_dim(action_dim)
        .with_emb_dim(emb)
        .with_frame_attention_norm(Some(true));
    let entries = entries(&unet, shapes);
    Ok(Plan { unet, entries })
}

/// The key table under construction.
struct Table<'a> {
    out: Vec<Entry>,
    shapes: &'a BTreeMap<String, Vec<usize>>,
    head_dim: usize,
}

impl Table<'_> {
    fn push(&mut self, key: String, ours: String, transform: Transform) {
        self.out.push(Entry { key, ours, transform });
    }

    /// A factorised convolution: spatial, then (k > 1) temporal.
    fn conv(&mut self, off: &str, ours: &str, temporal: bool) {
        let parts: &[(&str, &str)] = if temporal {
            &[("spatial_conv", "spatial"), ("temporal_conv", "temporal")]
        } else {
            &[("spatial_conv", "spatial")]
        };
        for (o, u) in parts {
            for p in ["weight", "bias"] {
                self.push(format!("{off}.{o}.{p}"), format!("{ours}.{u}.{p}"), Transform::Same);
            }
        }
    }

    fn norm(&mut self, off: &str, ours: &str) {
        self.push(format!("{off}.weight"), format!("{ours}.gamma"), Transform::Same);
        self.push(format!("{off}.bias"), format!("{ours}.beta"), Transform::Same);
    }

    /// A residual block, with its 1×1 skip when the file has one.
    fn res(&mut self, off: &str, ours: &str) {
        self.norm(&format!("{off}.in_layers.0"), &format!("{ours}.norm1"));
        self.conv(&format!("{off}.in_layers.2"), &format!("{ours}.conv1"), true);
        self.push(format!("{off}.emb_layers.1.weight"), format!("{ours}.film.weight"), Transform::Transpose);
        self.push(format!("{off}.emb_layers.1.bias"), format!("{ours}.film.bias"), Transform::Same);
        self.norm(&format!("{off}.out_layers.0"), &format!("{ours}.norm2"));
        self.conv(&format!("{off}.out_layers.3"), &format!("{ours}.conv2"), true);
        if self.shapes.contains_key(&format!("{off}.skip_connection.spatial_conv.weight")) {
            self.conv(&format!("{off}.skip_connection"), &format!("{ours}.skip"), false);
        }
    }

    /// An attention block over `c` channels.
    fn attn(&mut self, off: &str, ours: &str, c: usize) {
        let heads = (c / self.head_dim.max(1)).max(1);
        self.norm(&format!("{off}.norm"), &format!("{ours}.norm"));
        self.push(format!("{off}.qkv.weight"), format!("{ours}.qkv.weight"), Transform::Qkv { heads });
        self.push(format!("{off}.qkv.bias"), format!("{ours}.qkv.bias"), Transform::Qkv { heads });
        self.push(format!("{off}.proj_out.weight"), format!("{ours}.proj.weight"), Transform::Same);
        self.push(format!("{off}.proj_out.bias"), format!("{ours}.proj.bias"), Transform::Same);
    }
}

/// Every official key of `unet`'s layout, in the official order, with its place in [`UNet`]
/// (the walk of [`UNetConfig::init`], with the official block numbering).
fn entries(unet: &UNetConfig, shapes: &BTreeMap<String, Vec<usize>>) -> Vec<Entry> {
    let mut t = Table { out: Vec::new(), shapes, head_dim: unet.head_dim };
    for (off, ours) in [("action_embed.0", "act1"), ("action_embed.2", "act2")] {
        t.push(format!("{off}.weight"), format!("{ours}.weight"), Transform::Transpose);
        t.push(format!("{off}.bias"), format!("{ours}.bias"), Transform::Same);
    }
    t.conv("input_blocks.0.0", "conv_in", true);
    let (r, levels, mc) = (unet.res_blocks, unet.channel_mult.len(), unet.model_channels);
    let (mut idx, mut rate) = (1, 1);
    for (l, m) in unet.channel_mult.iter().enumerate() {
        for i in 0..r {
            let ours = format!("enc.{}", l * r + i);
            t.res(&format!("input_blocks.{idx}.0"), &format!("{ours}.res"));
            if unet.attention_rates.contains(&rate) {
                t.attn(&format!("input_blocks.{idx}.1"), &format!("{ours}.attn"), m * mc);
            }
            idx += 1;
        }
        if l + 1 < levels {
            t.conv(&format!("input_blocks.{idx}.0.op"), &format!("downs.{l}"), true);
            idx += 1;
            rate *= 2;
        }
    }
    let top = unet.channel_mult.last().copied().unwrap_or(1) * mc;
    t.res("middle_block.0", "mid.0");
    t.attn("middle_block.1", "mid_attn", top);
    t.res("middle_block.2", "mid.1");
    let mut j = 0;
    for (k, (l, m)) in unet.channel_mult.iter().enumerate().rev().enumerate() {
        for i in 0..=r {
            let ours = format!("dec.{}", k * (r + 1) + i);
            t.res(&format!("output_blocks.{j}.0"), &format!("{ours}.res"));
            let mut sub = 1;
            if unet.attention_rates.contains(&rate) {
                t.attn(&format!("output_blocks.{j}.1"), &format!("{ours}.attn"), m * mc);
                sub = 2;
            }
            if l > 0 && i == r {
                t.conv(&format!("output_blocks.{j}.{sub}.conv"), &format!("ups.{k}"), true);
                rate /= 2;
            }
            j += 1;
        }
    }
    t.norm("out.0", "norm_out");
    t.conv("out.2", "conv_out", true);
    t.out
}

/// Head-major qkv rows (`[head][q, k, v][d]`) to q/k/v-major (`[q, k, v][head][d]`): row
/// `h·3d + p·d + j` moves to `p·c + h·d + j` (c = heads·d), each row `row` values long.
pub fn permute_qkv(values: &[f32], heads: usize, row: usize) -> Vec<f32> {
    let rows = values.len() / row.max(1);
    let d = rows / 3 / heads.max(1);
    let c = heads * d;
    let mut out = vec![0.0; values.len()];
    for h in 0..heads {
        for p in 0..3 {
            for j in 0..d {
                let (old, new) = (h * 3 * d + p * d + j, p * c + h * d + j);
                out[new * row..(new + 1) * row].copy_from_slice(&values[old * row..(old + 1) * row]);
            }
        }
    }
    out
}

/// The official shape of a parameter whose burn shape is `ours`.
fn official_shape(ours: &[usize], t: Transform) -> Vec<usize> {
    match (t, ours) {
        (Transform::Transpose, &[i, o]) => vec![o, i],
        _ => ours.to_vec(),
    }
}

/// An imported world model, ready to be written.
pub struct Imported {
    /// Its configuration (pixel family, no autoencoder).
    pub config: WorldModelConfig,
    /// The U-Net with the imported weights.
    pub unet: UNet,
    /// What was read.
    pub record: ImportRecord,
}

/// Imports `path`'s `weights` copy with what `preset` supplies, for frames of `image_size`²
/// (`None`: the preset's).
///
/// # Errors
/// [`ImportError`] naming the file and the key at fault; [`ImportError::Layout`] when the
/// preset's action size differs from the file's or the frames cannot be downsampled evenly.
pub fn import(
    path: &Path,
    weights: Weights,
    preset: Preset,
    image_size: Option<usize>,
    sha256: String,
) -> Result<Imported, ImportError> {
    let source = Source::open(path, Some("model"), weights.prefix())?;
    let shapes = source.shapes();
    let plan = plan(&shapes, preset, path)?;
    let layout = |what: String| ImportError::Layout { path: path.into(), what };
    // What the preset assumes must fit what the file holds.
    let actions = preset.actions().dim();
    if plan.unet.action_dim != actions {
        return Err(layout(format!(
            "key `{}` reads {}-D actions, but the {preset:?} preset's are {actions}-D (another --preset?)",
            source.shown("action_embed.0.weight"),
            plan.unet.action_dim
        )));
    }
    let side = image_size.unwrap_or(preset.image_size());
    let halvings = 1 << (plan.unet.channel_mult.len() - 1);
    if side == 0 || !side.is_multiple_of(halvings) {
        return Err(layout(format!(
            "frames of {side}² cannot be halved {} times by the U-Net's downsamplings (a multiple of {halvings})",
            plan.unet.channel_mult.len() - 1
        )));
    }
    let mapped: BTreeSet<&str> = plan.entries.iter().map(|e| e.key.as_str()).collect();
    let unexpected: Vec<String> =
        source.names().filter(|n| !mapped.contains(n)).map(|n| source.shown(n)).collect();
    if !unexpected.is_empty() {
        return Err(ImportError::Unexpected { path: path.into(), keys: unexpected });
    }
    let device = Device::flex();
    let unet = plan.unet.init(&device);
    let ours = module_shapes(&unet);
    let apply = |what: String| ImportError::Apply { path: path.into(), what };
    let mut values = BTreeMap::new();
    let mut parameters = 0;
    for e in &plan.entries {
        let our_shape =
            ours.get(&e.ours).ok_or_else(|| apply(format!("no parameter `{}` for `{}`", e.ours, e.key)))?;
        let mut v = source.f32s(&e.key, &official_shape(our_shape, e.transform))?;
        v = match (e.transform, our_shape.as_slice()) {
            (Transform::Same, _) => v,
            (Transform::Transpose, &[i, o]) => transpose(&v, i, o),
            (Transform::Qkv { heads }, s) => permute_qkv(&v, heads, s[1..].iter().product()),
            (Transform::Transpose, s) => return Err(apply(format!("`{}` is not a matrix: {s:?}", e.ours))),
        };
        parameters += v.len();
        values.insert(e.ours.clone(), TensorData::new(v, our_shape.clone()));
    }
    let unet = place_all(unet, values, path)?;
    let mut config = WorldModelConfig::pixels(plan.unet, side);
    config.future = preset.future();
    config.actions = (preset != Preset::Pusht).then(|| preset.actions());
    let record = ImportRecord {
        format: "driftworld".into(),
        source: path.into(),
        sha256,
        step: top_level_int(path, "step"),
        weights,
        preset,
        tensors: plan.entries.len(),
        parameters,
    };
    Ok(Imported { config, unet, record })
}
