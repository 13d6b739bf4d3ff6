//! The imported policies' ResNet-18 frame encoder ([`ResNet18Gn`]), and the reward predictors'
//! ([`ResNet18`]), on the project's CPU kernels: every convolution one im2col matrix product over a group of images, GroupNorm and
//! ReLU fused after it, the 3×3 max-pool and the residual sums in plain loops.
//!
//! Why: once the imported U-Net ran on [`crate::cpu_unet`], burn-flex's convolutions of the
//! encoder were about a fifth of a full-size GPC policy's decision (BENCHMARKS.md, 2026-12-03).
//! The products run on the same [`Products`] as the policy's U-Net (for imported policies the
//! same-bits kernels of [`kernels::chain_gemm`], so the encoder's features, like the U-Net's
//! noise, are the same bits on every CPU and for any batch). Equal to burn's output within
//! float rounding (tested below).
//!
//! Inside, maps are `[c, n, h, w]` (channel-major, then image); the interface takes and
//! returns burn's `[n, c, h, w]`.

use burn::nn::conv::Conv2d;
use burn::nn::{GroupNorm, PaddingConfig2d};
use kernels::direct_conv::Norm;
use kernels::matrix::{Conv2dShape, group_norm_cols};
use nn::weights::{UnsupportedLayer, bias_values, norm_of, values};

use crate::cpu_unet::Products;
use crate::resnet::{self, ResNet18};
use crate::resnet_gn::{BlockGn, ConvNorm, ResNet18Gn};

/// Images encoded together: their im2col columns (at most 64 × 9 rows × 16 · 24² columns at
/// the first stage, 21 MB) stay a bounded size for any batch. Every column's sums are the
/// same whichever group it is in.
const GROUP: usize = 16;

/// A convolution with the GroupNorm after it (none where a BatchNorm was folded into it).
#[derive(Clone, Debug)]
struct ConvGn {
    cin: usize,
    cout: usize,
    shape: Conv2dShape,
    /// `[c_out, c_in·k·k]`, rows in im2col's order.
    w: Vec<f32>,
    b: Vec<f32>,
    norm: Option<Norm>,
}

impl ConvGn {
    fn new(c: &ConvNorm, layer: &str) -> Result<Self, UnsupportedLayer> {
        Self::of(&c.conv, c.norm.as_ref(), layer)
    }

    /// `conv`, then `norm` where there is one.
    fn of(conv: &Conv2d, norm: Option<&GroupNorm>, layer: &str) -> Result<Self, UnsupportedLayer> {
        let [k, kw] = conv.kernel_size;
        let [s, sw] = conv.stride;
        let p = k / 2;
        let same = matches!(conv.padding, PaddingConfig2d::Explicit(t, l, b, r) if [t, l, b, r] == [p; 4]);
        if k != kw || s != sw || conv.dilation != [1, 1] || conv.groups != 1 || !same {
            return Err(UnsupportedLayer::new(
                layer,
                "only square convolutions with one stride, padding k/2, dilation 1 and one group are supported",
            ));
        }
        let wt = conv.weight.val();
        let [cout, cin, _, _] = wt.dims();
        Ok(Self {
            cin,
            cout,
            shape: Conv2dShape { k, stride: s, pad: p },
            w: values(wt, layer)?,
            b: bias_values(&conv.bias, cout, layer)?,
            norm: norm.map(|n| norm_of(n, layer)).transpose()?,
        })
    }

    /// `x: [c_in, n, h, w]` → `[c_out, n, h', w']` (normed, then ReLU if `relu`), with h', w'.
    fn forward(
        &self,
        pr: Products,
        x: &[f32],
        (n, h, w): (usize, usize, usize),
        relu: bool,
    ) -> (Vec<f32>, usize, usize) {
        let (ho, wo) = (self.shape.out(h), self.shape.out(w));
        let cols = n * ho * wo;
        let mut y: Vec<f32> = self.b.iter().flat_map(|&b| std::iter::repeat_n(b, cols)).collect();
        let (k, s) = (self.shape.k, self.shape.stride);
        if k == 1 && s == 1 {
            pr.matmul((self.cout, self.cin, cols), &self.w, x, &mut y, true);
        } else {
            let mut col = kernels::elementwise::zeros(self.cin * k * k * cols);
            self.shape.im2col(x, self.cin, n, h, w, 0, n, &mut col);
            pr.matmul((self.cout, self.cin * k * k, cols), &self.w, &col, &mut y, true);
        }
        let act = |v: f32| if relu { v.max(0.0) } else { v };
        match &self.norm {
            Some(norm) => group_norm_cols(&mut y, norm, n, 1, ho * wo, None, act),
            None if relu => y.iter_mut().for_each(|v| *v = act(*v)),
            None => {}
        }
        (y, ho, wo)
    }
}

/// A basic block: conv-norm-ReLU-conv-norm plus the (projected) input, then ReLU.
#[derive(Clone, Debug)]
struct Block {
    c1: ConvGn,
    c2: ConvGn,
    down: Option<ConvGn>,
}

impl Block {
    fn new(b: &BlockGn, layer: &str) -> Result<Self, UnsupportedLayer> {
        Ok(Self {
            c1: ConvGn::new(&b.c1, &format!("{layer}.c1"))?,
            c2: ConvGn::new(&b.c2, &format!("{layer}.c2"))?,
            down: b.down.as_ref().map(|d| ConvGn::new(d, &format!("{layer}.down"))).transpose()?,
        })
    }

    /// A block of [`ResNet18`] (its BatchNorms folded into the convolutions).
    fn folded(b: &resnet::Block, layer: &str) -> Result<Self, UnsupportedLayer> {
        Ok(Self {
            c1: ConvGn::of(&b.conv1, None, &format!("{layer}.conv1"))?,
            c2: ConvGn::of(&b.conv2, None, &format!("{layer}.conv2"))?,
            down: b.down.as_ref().map(|d| ConvGn::of(d, None, &format!("{layer}.down"))).transpose()?,
        })
    }

    fn forward(&self, pr: Products, x: &[f32], (n, h, w): (usize, usize, usize)) -> (Vec<f32>, usize, usize) {
        let (a, ho, wo) = self.c1.forward(pr, x, (n, h, w), true);
        let (mut y, _, _) = self.c2.forward(pr, &a, (n, ho, wo), false);
        let skip = self.down.as_ref().map(|d| d.forward(pr, x, (n, h, w), false).0);
        let skip = skip.as_deref().unwrap_or(x);
        y.iter_mut().zip(skip).for_each(|(v, s)| *v = (*v + s).max(0.0));
        (y, ho, wo)
    }
}

/// [`ResNet18Gn`] without its average pool, on the CPU kernels.
#[derive(Clone, Debug)]
pub struct CpuResNet18 {
    stem: ConvGn,
    blocks: Vec<Block>,
    products: Products,
}

impl CpuResNet18 {
    /// Copies `r`'s weights; its products will run on `products`' kernels.
    ///
    /// # Errors
    /// [`UnsupportedLayer`] for a convolution these kernels do not run or weights that are not
    /// f32.
    pub fn new(r: &ResNet18Gn, products: Products) -> Result<Self, UnsupportedLayer> {
        let blocks = r.blocks.iter().enumerate().map(|(i, b)| Block::new(b, &format!("blocks.{i}")));
        Ok(Self { stem: ConvGn::new(&r.stem, "stem")?, blocks: blocks.collect::<Result<_, _>>()?, products })
    }

    /// Copies the weights of torchvision's ResNet-18 with its BatchNorms folded ([`ResNet18`],
    /// GPC's reward predictors).
    ///
    /// # Errors
    /// As [`Self::new`].
    pub fn folded(r: &ResNet18, products: Products) -> Result<Self, UnsupportedLayer> {
        let blocks = r.blocks.iter().enumerate().map(|(i, b)| Block::folded(b, &format!("blocks.{i}")));
        let stem = ConvGn::of(&r.stem, None, "stem")?;
        Ok(Self { stem, blocks: blocks.collect::<Result<_, _>>()?, products })
    }

    /// The global average pool of [`Self::features`] ([`ResNet18Gn::forward`], [`ResNet18::forward`]).
    ///
    /// # Shapes
    /// `x: [n, 3, h, w]` in [0, 1] → `[n, c]`
    pub fn pooled(&self, x: &[f32], n: usize, (h, w): (usize, usize)) -> (Vec<f32>, usize) {
        let (f, [c, fh, fw]) = self.features(x, n, (h, w));
        let area = (fh * fw).max(1);
        (f.chunks(area).map(|plane| plane.iter().sum::<f32>() / area as f32).collect(), c)
    }

    /// The last map, before the pool ([`ResNet18Gn::features`]).
    ///
    /// # Shapes
    /// `x: [n, 3, h, w]` in [0, 1] → (`[n, c, h', w']`, c, h', w')
    pub fn features(&self, x: &[f32], n: usize, (h, w): (usize, usize)) -> (Vec<f32>, [usize; 3]) {
        let mut out = Vec::new();
        let mut dims = [0; 3];
        for i0 in (0..n).step_by(GROUP) {
            let g = GROUP.min(n - i0);
            let (y, d) = self.features_cm(
                &nchw_to_cm(&x[i0 * 3 * h * w..(i0 + g) * 3 * h * w], g, 3, h * w),
                g,
                (h, w),
            );
            out.extend(nchw_to_cm(&y, d[0], g, d[1] * d[2]));
            dims = d;
        }
        (out, dims)
    }

    /// [`Self::features`] of `n` images laid out `[3, n, h, w]`, returned `[c, n, h', w']`.
    fn features_cm(&self, x: &[f32], n: usize, (h, w): (usize, usize)) -> (Vec<f32>, [usize; 3]) {
        let pr = self.products;
        let (y, h, w) = self.stem.forward(pr, x, (n, h, w), true);
        let (mut y, mut h, mut w) = max_pool3s2(&y, self.stem.cout * n, h, w);
        for b in &self.blocks {
            (y, h, w) = b.forward(pr, &y, (n, h, w));
        }
        let c = y.len() / (n * h * w).max(1);
        (y, [c, h, w])
    }
}

/// `[a, b, l]` → `[b, a, l]`: burn's `[n, c, h·w]` to channel-major `[c, n, h·w]` and back.
fn nchw_to_cm(x: &[f32], a: usize, b: usize, l: usize) -> Vec<f32> {
    let mut y = vec![0.0; x.len()];
    for i in 0..a {
        for j in 0..b {
            y[(j * a + i) * l..][..l].copy_from_slice(&x[(i * b + j) * l..][..l]);
        }
    }
    y
}

/// 3×3 max-pool, stride 2, padding 1 (padding never wins) on `planes` maps of `h × w`.
fn max_pool3s2(x: &[f32], planes: usize, h: usize, w: usize) -> (Vec<f32>, usize, usize) {
    let (ho, wo) = ((h + 2 - 3) / 2 + 1, (w + 2 - 3) / 2 + 1);
    let mut y = vec![0.0; planes * ho * wo];
    for (src, dst) in x.chunks_exact(h * w).zip(y.chunks_exact_mut(ho * wo)) {
        for oy in 0..ho {
            let rows = (2 * oy).saturating_sub(1)..(2 * oy + 2).min(h);
            for ox in 0..wo {
                let cols = (2 * ox).saturating_sub(1)..(2 * ox + 2).min(w);
                let mut m = f32::NEG_INFINITY;
                for iy in rows.clone() {
                    m = src[iy * w + cols.start..iy * w + cols.end].iter().fold(m, |m, &v| m.max(v));
                }
                dst[oy * wo + ox] = m;
            }
        }
    }
    (y, ho, wo)
}

#[cfg(test)]
mod tests {
    use burn::module::Module;
    use burn::tensor::{Device, Distribution, Tensor};
    use nn::weights::Jitter;

    use super::*;
    use crate::resnet_gn::BackboneNorm;

    #[test]
    fn max_pool_by_hand() {
        // A 4×4 map 0..16: output (0, 0) covers rows and columns 0..2 → max 5; (0, 1) rows 0..2,
        // columns 1..4 → 7; (1, 0) rows 1..4, columns 0..2 → 13; (1, 1) → 15.
        let x: Vec<f32> = (0..16).map(|v| v as f32).collect();
        assert_eq!(max_pool3s2(&x, 1, 4, 4), (vec![5.0, 7.0, 13.0, 15.0], 2, 2));
    }

    #[test]
    fn a_folded_resnet_pools_what_burn_pools() {
        // torchvision's layout with BatchNorms folded (GPC's reward predictors), base 8, 5 frames
        // of 36² (maps 18, 9, 5, 3, 2, 1).
        let device = Device::flex();
        let net = ResNet18::new(8, &device).map(&mut Jitter);
        let x = Tensor::<4>::random([5, 3, 36, 36], Distribution::Uniform(0.0, 1.0), &device);
        let want: Vec<f32> = net.forward(x.clone()).into_data().try_to_vec().unwrap_or_default();
        let xs: Vec<f32> = x.into_data().try_to_vec().unwrap_or_default();
        let cpu = CpuResNet18::folded(&net, Products::Chain).unwrap_or_else(|e| panic!("{e}"));
        let (got, c) = cpu.pooled(&xs, 5, (36, 36));
        assert_eq!((got.len(), c), (want.len(), 64));
        let scale = want.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
        let max = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(scale > 1e-2 && max < 1e-4 * scale.max(1.0), "max difference {max} (scale {scale})");
    }

    #[test]
    fn encodes_what_burn_encodes() {
        // Base 16 (GroupNorm of one group per 16 channels), both norms; 19 images (a full group
        // of 16 and 3 more) of 40² (odd maps on the way: 20, 10, 5, 3, 2).
        let device = Device::flex();
        for norm in [BackboneNorm::Group, BackboneNorm::FoldedBatch] {
            let net = ResNet18Gn::new(16, norm, &device).map(&mut Jitter);
            let n = 19;
            let x = Tensor::<4>::random([n, 3, 40, 40], Distribution::Uniform(0.0, 1.0), &device);
            let want = net.features(x.clone());
            let wd = want.dims();
            let want: Vec<f32> = want.into_data().try_to_vec().unwrap_or_default();
            let xs: Vec<f32> = x.into_data().try_to_vec().unwrap_or_default();
            let scale = want.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
            assert!(scale > 1e-2, "degenerate test output");
            for products in [Products::GemmCrate, Products::Chain] {
                let cpu = CpuResNet18::new(&net, products).unwrap_or_else(|e| panic!("{e}"));
                let (got, d) = cpu.features(&xs, n, (40, 40));
                assert_eq!([n, d[0], d[1], d[2]], wd);
                let max = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
                assert!(
                    max < 1e-4 * scale.max(1.0),
                    "{norm:?} {products:?}: max difference {max} (scale {scale})"
                );
            }
        }
    }
}
