//! The diffusion policy's frame encoder on the CPU without burn: the same network
//! as [`ObsEncoder::forward`], on the world model's direct 3x3 kernels
//! ([`kernels::direct_conv`]) for the stride-1 residual blocks and on matrix
//! products (im2col + the `gemm` crate) for the stride-2 downsampling convolutions.
//!
//! Why: once the U-Net ran on [`crate::cpu_unet`], encoding the two observed frames
//! was most of a decision's remaining cost, mostly burn-flex's per-layer overhead.
//! A [`DiffusionPolicy`](crate::diffusion::DiffusionPolicy) on the Flex device
//! encodes with this; training keeps burn's path. The two agree to float rounding
//! (tested below).

use burn::nn::conv::Conv2d;
use kernels::direct_conv::{Conv3x3, Norm};
use kernels::matrix::{Conv2dShape, matmul};
use kernels::padded::Padded;
use nn::UnsupportedLayer;
use nn::weights::{ConvWeights, bias_values, conv3x3_of, conv3x3_weights, norm_of, values};

use crate::net::{ObsEncoder, Res2d};

/// A 3x3, stride-2, padding-1 convolution as im2col + one matrix product.
#[derive(Clone, Debug)]
struct Down {
    cin: usize,
    cout: usize,
    /// `[c_out, c_in·9]`
    w: Vec<f32>,
    b: Vec<f32>,
}

impl Down {
    fn new(c: &Conv2d, layer: &str) -> Result<Self, UnsupportedLayer> {
        let ConvWeights { cin, cout, weight, bias } = conv3x3_weights(c, layer, 2)?; // weight: [cout, cin, 3, 3]
        Ok(Self { cin, cout, w: weight, b: bias.unwrap_or_else(|| vec![0.0; cout]) })
    }

    /// `[c_in, s, s] -> [c_out, s/2, s/2]` (s even).
    fn forward(&self, x: &[f32], s: usize) -> Vec<f32> {
        let so = s / 2;
        let cols = so * so;
        let mut col = vec![0.0; self.cin * 9 * cols];
        Conv2dShape { k: 3, stride: 2, pad: 1 }.im2col(x, self.cin, 1, s, s, 0, 1, &mut col);
        let mut y: Vec<f32> = self.b.iter().flat_map(|&b| std::iter::repeat_n(b, cols)).collect();
        matmul(self.cout, self.cin * 9, cols, &self.w, &col, &mut y, true);
        y
    }
}

/// GN → SiLU → conv, twice, plus the input ([`Res2d`]).
#[derive(Clone, Debug)]
struct Block {
    n1: Norm,
    c1: Conv3x3,
    n2: Norm,
    c2: Conv3x3,
}

/// The encoder's weights, laid out for the direct kernels.
#[derive(Clone, Debug)]
pub struct CpuEncoder {
    downs: Vec<Down>,
    blocks: Vec<Block>,
    norm: Norm,
    /// Final linear layer, burn's layout `[d_in, d_out]`.
    out_w: Vec<f32>,
    out_b: Vec<f32>,
    features: usize,
}

impl CpuEncoder {
    /// Copies `e`'s weights.
    ///
    /// # Errors
    /// [`UnsupportedLayer`] naming the layer these kernels cannot run.
    pub fn new(e: &ObsEncoder) -> Result<Self, UnsupportedLayer> {
        let block = |b: &Res2d, i: usize| -> Result<Block, UnsupportedLayer> {
            Ok(Block {
                n1: norm_of(&b.n1, &format!("blocks.{i}.n1"))?,
                c1: conv3x3_of(&b.c1, &format!("blocks.{i}.c1"))?,
                n2: norm_of(&b.n2, &format!("blocks.{i}.n2"))?,
                c2: conv3x3_of(&b.c2, &format!("blocks.{i}.c2"))?,
            })
        };
        let w = e.out.weight.val();
        let [_, features] = w.dims();
        let out_w = values(w, "out")?;
        let out_b = bias_values(&e.out.bias, features, "out")?;
        Ok(Self {
            downs: e
                .downs
                .iter()
                .enumerate()
                .map(|(i, d)| Down::new(d, &format!("downs.{i}")))
                .collect::<Result<_, _>>()?,
            blocks: e.blocks.iter().enumerate().map(|(i, b)| block(b, i)).collect::<Result<_, _>>()?,
            norm: norm_of(&e.norm, "norm")?,
            out_w,
            out_b,
            features,
        })
    }

    /// Encodes `n` frames.
    ///
    /// # Shapes
    /// `[n, 3, s, s]` in [-1, 1] → `[n, features]`
    pub fn forward(&self, frames: &[f32], n: usize, s: usize) -> Vec<f32> {
        let per = frames.len() / n.max(1);
        let mut flat = Vec::new();
        for x in frames.chunks(per).take(n) {
            let mut h = x.to_vec();
            let mut side = s;
            for (i, down) in self.downs.iter().enumerate() {
                h = down.forward(&h, side);
                side /= 2;
                if let Some(b) = self.blocks.get(i) {
                    h = residual(b, h, side);
                }
            }
            // silu(groupnorm(h)), flattened [c·side²]
            let mut pad = Padded::zeros(h.len() / (side * side), side, side);
            pad.fill_norm_silu(&h, &self.norm);
            flat.extend(pad.interior());
        }
        let din = flat.len() / n.max(1);
        let mut y: Vec<f32> = (0..n).flat_map(|_| self.out_b.iter().copied()).collect();
        matmul(n, din, self.features, &flat, &self.out_w, &mut y, true);
        y
    }
}

/// `x + c2(silu(n2(c1(silu(n1(x))))))` on `[c, side, side]`.
fn residual(b: &Block, x: Vec<f32>, side: usize) -> Vec<f32> {
    let c = b.c1.cin();
    let mut pad = Padded::zeros(c, side, side);
    pad.fill_norm_silu(&x, &b.n1);
    let mut t = vec![0.0; c * side * side];
    b.c1.forward(&pad, None, &mut t);
    pad.fill_norm_silu(&t, &b.n2);
    b.c2.forward(&pad, Some(&x), &mut t);
    t
}

#[cfg(test)]
mod tests {
    use burn::module::Module;
    use burn::tensor::{Device, Distribution, Tensor};
    use nn::weights::Jitter;

    use super::*;
    use crate::net::NetConfig;

    #[test]
    fn encodes_what_burn_encodes() {
        let device = Device::flex();
        let cfg = NetConfig { encoder_width: 8, ..NetConfig::new() };
        let enc = ObsEncoder::new(&cfg, &device).map(&mut Jitter);
        let cpu = CpuEncoder::new(&enc).unwrap_or_else(|e| panic!("{e}"));
        let x = Tensor::<4>::random([3, 3, 96, 96], Distribution::Uniform(-1.0, 1.0), &device);
        let want: Vec<f32> = enc.forward(x.clone()).into_data().try_to_vec().unwrap_or_default();
        let got = cpu.forward(&x.into_data().try_to_vec::<f32>().unwrap_or_default(), 3, 96);
        assert_eq!(got.len(), 3 * cfg.feature_dim);
        let scale = want.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
        let max = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(scale > 1e-2, "degenerate test output");
        assert!(max < 1e-4 * scale.max(1.0), "max difference {max} (output scale {scale})");
    }
}
