//! The vision encoder of imported diffusion policies: torchvision's ResNet-18 with its classifier
//! removed, with every BatchNorm replaced by GroupNorm(C/16, C) (diffusion_policy's
//! `replace_bn_with_gn`: DriftWorld/GPC's Push-T policies, robomimic's, LeRobot's default) or
//! with its eval-mode BatchNorms kept, folded into the convolutions before them (LeRobot's
//! `use_group_norm: false`, [`BackboneNorm::FoldedBatch`]; see [`crate::resnet::fold_batch_norm`]).
//!
//! Stem: 7×7 stride-2 conv, its norm, ReLU, 3×3 stride-2 max-pool; four stages of two basic
//! blocks (base·1, 2, 4, 8 channels; stages 2–4 start at stride 2 with a 1×1 projection and its
//! norm on the skip); global average pool to 8·base features. With GroupNorm the convolutions
//! have no bias; folded, each has the bias its BatchNorm left and no norm follows. At 96² the
//! map is 3×3 before the pool.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::pool::{AdaptiveAvgPool2d, AdaptiveAvgPool2dConfig, MaxPool2d, MaxPool2dConfig};
use burn::nn::{GroupNorm, GroupNormConfig, PaddingConfig2d};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::resnet::widths;

/// How the backbone's convolutions are normalised.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BackboneNorm {
    /// GroupNorm(C/16, C) after each bias-free convolution.
    #[default]
    Group,
    /// torchvision's BatchNorms in eval mode, folded into the convolutions (each with a bias).
    FoldedBatch,
}

impl BackboneNorm {
    /// Whether this is the GroupNorm backbone (what `policy.json` leaves out).
    pub fn is_group(&self) -> bool {
        *self == Self::Group
    }
}

/// Channels per GroupNorm group (diffusion_policy's `replace_bn_with_gn`).
pub const FEATURES_PER_GROUP: usize = 16;

/// A `k×k` convolution with "same" padding (torchvision's), with a bias or without.
fn conv(cin: usize, cout: usize, k: usize, stride: usize, bias: bool, device: &Device) -> Conv2d {
    let p = k / 2;
    Conv2dConfig::new([cin, cout], [k, k])
        .with_stride([stride, stride])
        .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
        .with_bias(bias)
        .init(device)
}

fn norm(c: usize, device: &Device) -> GroupNorm {
    GroupNormConfig::new(c / FEATURES_PER_GROUP, c).init(device)
}

/// A conv and the GroupNorm after it (none where a BatchNorm was folded into the conv).
#[derive(Module, Debug)]
pub struct ConvNorm {
    /// The convolution.
    pub conv: Conv2d,
    /// Its GroupNorm.
    pub norm: Option<GroupNorm>,
}

impl ConvNorm {
    fn new(cin: usize, cout: usize, k: usize, stride: usize, n: BackboneNorm, device: &Device) -> Self {
        let folded = n == BackboneNorm::FoldedBatch;
        Self { conv: conv(cin, cout, k, stride, folded, device), norm: (!folded).then(|| norm(cout, device)) }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let y = self.conv.forward(x);
        match &self.norm {
            Some(n) => n.forward(y),
            None => y,
        }
    }
}

/// A basic block: conv-GN-ReLU-conv-GN plus the (projected) input, then ReLU.
#[derive(Module, Debug)]
pub struct BlockGn {
    /// 3×3, stride 1 or 2.
    pub c1: ConvNorm,
    /// 3×3.
    pub c2: ConvNorm,
    /// 1×1 projection of the skip where the shape changes.
    pub down: Option<ConvNorm>,
}

impl BlockGn {
    fn new(cin: usize, cout: usize, stride: usize, n: BackboneNorm, device: &Device) -> Self {
        Self {
            c1: ConvNorm::new(cin, cout, 3, stride, n, device),
            c2: ConvNorm::new(cout, cout, 3, 1, n, device),
            down: (stride != 1 || cin != cout).then(|| ConvNorm::new(cin, cout, 1, stride, n, device)),
        }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let h = self.c2.forward(relu(self.c1.forward(x.clone())));
        let skip = match &self.down {
            Some(d) => d.forward(x),
            None => x,
        };
        relu(h + skip)
    }
}

/// ResNet-18 with GroupNorm or folded BatchNorms, without its classifier.
#[derive(Module, Debug)]
pub struct ResNet18Gn {
    /// The 7×7 stem and its GroupNorm.
    pub stem: ConvNorm,
    pool: MaxPool2d,
    /// Stages 1–4, two blocks each (`blocks[2 s + i]`).
    pub blocks: Vec<BlockGn>,
    avg: AdaptiveAvgPool2d,
}

impl ResNet18Gn {
    /// Fresh weights at base width `base` (64 for torchvision's; a multiple of 16 with
    /// GroupNorm), normalised as `n` says.
    pub fn new(base: usize, n: BackboneNorm, device: &Device) -> Self {
        let mut blocks = Vec::with_capacity(8);
        let mut cin = base;
        for (s, &w) in widths(base).iter().enumerate() {
            blocks.push(BlockGn::new(cin, w, if s == 0 { 1 } else { 2 }, n, device));
            blocks.push(BlockGn::new(w, w, 1, n, device));
            cin = w;
        }
        Self {
            stem: ConvNorm::new(3, base, 7, 2, n, device),
            pool: MaxPool2dConfig::new([3, 3])
                .with_strides([2, 2])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(),
            blocks,
            avg: AdaptiveAvgPool2dConfig::new([1, 1]).init(),
        }
    }

    /// The last map, before the pool.
    ///
    /// # Shapes
    /// `[n, 3, h, w]` → `[n, 8 base, ⌈h/32⌉, ⌈w/32⌉]`
    pub fn features(&self, x: Tensor<4>) -> Tensor<4> {
        let mut h = self.pool.forward(relu(self.stem.forward(x)));
        for b in &self.blocks {
            h = b.forward(h);
        }
        h
    }

    /// # Shapes
    /// `[n, 3, h, w]` in [0, 1] → `[n, 8 base]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<2> {
        self.pool(self.features(x))
    }

    /// The global average pool of [`Self::features`]' map.
    ///
    /// # Shapes
    /// `[n, c, h, w]` → `[n, c]`
    pub fn pool(&self, h: Tensor<4>) -> Tensor<2> {
        let [n, c, _, _] = h.dims();
        self.avg.forward(h).reshape([n, c])
    }
}
