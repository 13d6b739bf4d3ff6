//! ResNet-18 (He et al. 2016) as torchvision builds it, for networks imported from PyTorch,
//! with its BatchNorms folded into the convolutions before them (inference only: a BatchNorm
//! in eval mode is a per-channel affine map, so `bn(conv(x)) = conv'(x)` with
//! `w' = w·γ/√(σ²+ε)` and `b' = β − μ·γ/√(σ²+ε)`).
//!
//! Stem: 7×7 stride-2 conv, ReLU, 3×3 stride-2 max-pool; four stages of two basic blocks
//! (64, 128, 256, 512 channels; stages 2–4 start at stride 2 with a 1×1 projection on the
//! skip); global average pool to 512 features (8× the base width). At 96² the map is 3×3 before the pool.

use burn::module::Module;
use burn::nn::PaddingConfig2d;
use burn::nn::conv::Conv2d;
use burn::nn::pool::{AdaptiveAvgPool2d, AdaptiveAvgPool2dConfig, MaxPool2d, MaxPool2dConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};
use nn::layers::conv;

/// torchvision's base width (stage widths 64, 128, 256, 512).
pub const BASE: usize = 64;

/// BatchNorm's ε in torchvision's ResNet-18.
pub const BN_EPS: f32 = 1e-5;

/// An eval-mode BatchNorm (`gamma`, `beta`, running `mean` and `var`, ε = [`BN_EPS`]) folded
/// into the bias-free convolution before it: scales `w` (`[c_out, …]`, output channel major) in
/// place by `γ/√(σ²+ε)` and returns the bias `β − μ·γ/√(σ²+ε)`.
///
/// # Errors
/// The first output channel whose running variance is negative.
pub fn fold_batch_norm(
    w: &mut [f32],
    gamma: &[f32],
    beta: &[f32],
    mean: &[f32],
    var: &[f32],
) -> Result<Vec<f32>, usize> {
    if let Some(neg) = var.iter().position(|&v| v < 0.0) {
        return Err(neg);
    }
    let scale: Vec<f32> = gamma.iter().zip(var).map(|(g, v)| g / (v + BN_EPS).sqrt()).collect();
    let per = w.len() / scale.len().max(1);
    for (row, s) in w.chunks_mut(per.max(1)).zip(&scale) {
        row.iter_mut().for_each(|x| *x *= s);
    }
    Ok(beta.iter().zip(mean).zip(&scale).map(|((b, m), s)| b - m * s).collect())
}

/// Where a convolution that a BatchNorm follows sits in ResNet-18.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConvSite {
    /// The 7×7 stem.
    Stem,
    /// Block `b`'s (0–7) first 3×3 convolution.
    First(usize),
    /// Block `b`'s second 3×3 convolution.
    Second(usize),
    /// Block `b`'s 1×1 projection of the skip (blocks 2, 4 and 6, where a stage starts at
    /// stride 2 and doubles the width).
    Down(usize),
}

/// ResNet-18's convolutions that a BatchNorm follows, named as torchvision's children are in
/// a `Sequential` of them (`0` conv1, `1` bn1, `4`–`7` layer1–4, two blocks each): each
/// convolution's name, its BatchNorm's, and where it sits. What every importer of a BatchNorm
/// ResNet-18 folds.
pub fn batch_norm_sites() -> Vec<(String, String, ConvSite)> {
    let mut sites = vec![("0".to_string(), "1".to_string(), ConvSite::Stem)];
    for b in 0..8 {
        let k = format!("{}.{}", 4 + b / 2, b % 2);
        sites.push((format!("{k}.conv1"), format!("{k}.bn1"), ConvSite::First(b)));
        sites.push((format!("{k}.conv2"), format!("{k}.bn2"), ConvSite::Second(b)));
        if b > 0 && b % 2 == 0 {
            sites.push((format!("{k}.downsample.0"), format!("{k}.downsample.1"), ConvSite::Down(b)));
        }
    }
    sites
}

/// Stage widths for base width `base`: base·(1, 2, 4, 8).
pub fn widths(base: usize) -> [usize; 4] {
    [base, 2 * base, 4 * base, 8 * base]
}

/// A basic block: conv-ReLU-conv plus the (projected) input, then ReLU.
#[derive(Module, Debug)]
pub struct Block {
    /// 3×3, stride 1 or 2.
    pub conv1: Conv2d,
    /// 3×3.
    pub conv2: Conv2d,
    /// 1×1 projection of the skip where the shape changes.
    pub down: Option<Conv2d>,
}

impl Block {
    fn new(cin: usize, cout: usize, stride: usize, device: &Device) -> Self {
        Self {
            conv1: conv(cin, cout, 3, stride, device),
            conv2: conv(cout, cout, 3, 1, device),
            down: (stride != 1 || cin != cout).then(|| conv(cin, cout, 1, stride, device)),
        }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let h = self.conv2.forward(relu(self.conv1.forward(x.clone())));
        let skip = match &self.down {
            Some(d) => d.forward(x),
            None => x,
        };
        relu(h + skip)
    }
}

/// ResNet-18 without its classifier, BatchNorms folded.
#[derive(Module, Debug)]
pub struct ResNet18 {
    /// The 7×7 stem convolution.
    pub stem: Conv2d,
    pool: MaxPool2d,
    /// Stages 1–4, two blocks each (`blocks[2 s + i]`).
    pub blocks: Vec<Block>,
    avg: AdaptiveAvgPool2d,
}

impl ResNet18 {
    /// Fresh weights at base width `base` ([`BASE`] for torchvision's; smaller for tests).
    pub fn new(base: usize, device: &Device) -> Self {
        let mut blocks = Vec::with_capacity(8);
        let mut cin = base;
        for (s, &w) in widths(base).iter().enumerate() {
            blocks.push(Block::new(cin, w, if s == 0 { 1 } else { 2 }, device));
            blocks.push(Block::new(w, w, 1, device));
            cin = w;
        }
        Self {
            stem: conv(3, base, 7, 2, device),
            pool: MaxPool2dConfig::new([3, 3])
                .with_strides([2, 2])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(),
            blocks,
            avg: AdaptiveAvgPool2dConfig::new([1, 1]).init(),
        }
    }

    /// # Shapes
    /// `[n, 3, h, w]` → `[n, 8 base]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<2> {
        let mut h = self.pool.forward(relu(self.stem.forward(x)));
        for b in &self.blocks {
            h = b.forward(h);
        }
        let [n, c, _, _] = h.dims();
        self.avg.forward(h).reshape([n, c])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_folded_batch_norm_is_the_affine_map_it_replaces() {
        // Two output channels of two weights each. Channel 0: γ 2, β 1, μ 0.5, σ² 3 − ε, so
        // the scale is 2/√3 and the bias 1 − 0.5·2/√3 = 0.42265. Channel 1: γ 1, β 0, μ 0,
        // σ² 1 − ε: scale 1, bias 0.
        let mut w = vec![1.0, -3.0, 0.25, 4.0];
        let b = fold_batch_norm(&mut w, &[2.0, 1.0], &[1.0, 0.0], &[0.5, 0.0], &[3.0 - BN_EPS, 1.0 - BN_EPS])
            .expect("variances are positive");
        let s = 2.0 / 3f32.sqrt();
        let want = [s, -3.0 * s, 0.25, 4.0];
        assert!(w.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-6), "{w:?}");
        assert!((b[0] - 0.422_65).abs() < 1e-5 && b[1].abs() < 1e-7, "{b:?}");
        // A negative variance names its channel.
        assert_eq!(fold_batch_norm(&mut [1.0, 1.0], &[1.0, 1.0], &[0.0; 2], &[0.0; 2], &[1.0, -0.5]), Err(1));
    }

    #[test]
    fn the_batch_norm_sites_are_the_networks_projections_and_convolutions() {
        // 1 stem + 8 blocks × 2 + 3 projections = 20, each projection where `ResNet18`
        // builds one (the block's stride or width changes).
        let sites = batch_norm_sites();
        assert_eq!(sites.len(), 20);
        let net = ResNet18::new(8, &Device::flex());
        let downs: Vec<usize> = sites
            .iter()
            .filter_map(|(_, _, s)| if let ConvSite::Down(b) = s { Some(*b) } else { None })
            .collect();
        let built: Vec<usize> = (0..8).filter(|&b| net.blocks[b].down.is_some()).collect();
        assert_eq!(downs, built);
        assert_eq!(sites[0], ("0".into(), "1".into(), ConvSite::Stem));
        assert!(sites.contains(&("7.1.conv2".into(), "7.1.bn2".into(), ConvSite::Second(7))));
        assert!(sites.contains(&("5.0.downsample.0".into(), "5.0.downsample.1".into(), ConvSite::Down(2))));
    }
}
