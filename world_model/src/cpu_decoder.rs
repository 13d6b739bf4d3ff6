//! The frame autoencoder's decoder on the CPU without burn: the same network
//! as [`Autoencoder::decode`], run with the direct kernels of
//! [`crate::direct_conv`].
//!
//! `rank` and `wm eval` decode every frame a policy sees; with burn-flex that
//! was about half of `rank`'s CPU time. A [`WorldModel`](crate::model::WorldModel)
//! on the Flex (CPU) device builds one of these at load time and decodes with
//! it; training (which needs gradients) and GPU devices keep burn's path. The
//! two agree to float rounding (tested below).

use crate::autoencoder::{Autoencoder, ResBlock};
use kernels::direct_conv::{Conv3x3, Norm, winograd_enabled};
use kernels::padded::Padded;
use kernels::winograd::upsample::Upsample3x3;
use nn::weights::{UnsupportedLayer, conv3x3_of, conv3x3_weights, norm_of};

/// GroupNorm -> SiLU -> conv, twice, plus the input (as [`ResBlock`]).
#[derive(Clone, Debug)]
struct Block {
    norm1: Norm,
    conv1: Conv3x3,
    norm2: Norm,
    conv2: Conv3x3,
}

/// A `dec_up` layer: nearest 2x upsampling, then a 3x3 convolution.
#[derive(Clone, Debug)]
struct UpConv {
    /// On the upsampled map (`EVALHARNESS_CONV=direct`, or odd sides).
    conv: Conv3x3,
    /// Per output phase on the small map.
    phases: Upsample3x3,
}

impl UpConv {
    /// `src` `[cin, h, w]` upsampled and convolved: `[cout, 2h, 2w]`.
    fn forward(&self, src: &[f32], h: usize, w: usize) -> Vec<f32> {
        let mut out = kernels::elementwise::zeros(self.conv.cout() * 4 * h * w);
        if Upsample3x3::supports(h, w) && winograd_enabled() {
            let mut pad = Padded::zeros(self.conv.cin(), h, w);
            pad.fill(src, false);
            self.phases.forward(&pad, &mut out);
        } else {
            let mut pad = Padded::zeros(self.conv.cin(), 2 * h, 2 * w);
            pad.fill(src, true);
            self.conv.forward(&pad, None, &mut out);
        }
        out
    }
}

/// The decoder's weights, laid out for the direct kernels.
#[derive(Clone, Debug)]
pub struct CpuDecoder {
    latent_channels: usize,
    latent_size: usize,
    dec_in: Conv3x3,
    blocks: Vec<Block>,
    ups: Vec<UpConv>,
    norm: Norm,
    out: Conv3x3,
}

impl CpuDecoder {
    /// Copies the decoder half of `ae` (latents of `latent_size`²).
    ///
    /// # Errors
    /// [`UnsupportedLayer`] for a convolution that is not 3x3, stride 1, padding 1, or
    /// weights that are not f32.
    pub fn new(ae: &Autoencoder, latent_size: usize) -> Result<Self, UnsupportedLayer> {
        let block = |b: &ResBlock, name: &str| -> Result<Block, UnsupportedLayer> {
            Ok(Block {
                norm1: norm_of(&b.norm1, &format!("{name}.norm1"))?,
                conv1: conv3x3_of(&b.conv1, &format!("{name}.conv1"))?,
                norm2: norm_of(&b.norm2, &format!("{name}.norm2"))?,
                conv2: conv3x3_of(&b.conv2, &format!("{name}.conv2"))?,
            })
        };
        let dec_in = conv3x3_of(&ae.dec_in, "dec_in")?;
        Ok(Self {
            latent_channels: dec_in.cin(),
            latent_size,
            blocks: (ae.dec_blocks.iter().enumerate())
                .map(|(i, b)| block(b, &format!("dec_blocks.{i}")))
                .collect::<Result<_, _>>()?,
            ups: (ae.dec_up.iter().enumerate())
                .map(|(i, c)| {
                    let layer = format!("dec_up.{i}");
                    let w = conv3x3_weights(c, &layer, 1)?;
                    Ok(UpConv {
                        conv: Conv3x3::new(w.cin, w.cout, &w.weight, w.bias.as_deref()),
                        phases: Upsample3x3::new(w.cin, w.cout, &w.weight, w.bias.as_deref()),
                    })
                })
                .collect::<Result<_, UnsupportedLayer>>()?,
            norm: norm_of(&ae.dec_norm, "dec_norm")?,
            out: conv3x3_of(&ae.dec_out, "dec_out")?,
            dec_in,
        })
    }

    /// Decodes `b` latents `z` (`[b, C, s, s]`, row-major, not normalised) to raw frames.
    ///
    /// # Shapes
    /// `[b, C, s, s] -> [b, 3, 8s, 8s]`
    pub fn decode(&self, z: &[f32], b: usize) -> Vec<f32> {
        let (c, s) = (self.latent_channels, self.latent_size);
        let per = c * s * s;
        debug_assert_eq!(z.len(), b * per);
        let side = s << self.ups.len();
        let mut out = Vec::with_capacity(b * self.out.cout() * side * side);
        for zi in z.chunks(per) {
            out.extend(self.decode_one(zi));
        }
        out
    }

    /// One latent `[C, s, s]` to one frame `[3, 8s, 8s]`.
    fn decode_one(&self, z: &[f32]) -> Vec<f32> {
        let (c, mut side) = (self.latent_channels, self.latent_size);
        let mut pad = Padded::zeros(c, side, side);
        pad.fill(z, false);
        let mut h = kernels::elementwise::zeros(self.dec_in.cout() * side * side); // [c3, s, s]
        self.dec_in.forward(&pad, None, &mut h);
        h = self.block(&self.blocks[0], h, side);
        for (up, block) in self.ups.iter().zip(&self.blocks[1..]) {
            h = up.forward(&h, side, side); // nearest 2x, then the conv
            side *= 2;
            h = self.block(block, h, side);
        }
        let mut pad = Padded::zeros(self.out.cin(), side, side);
        pad.fill_norm_silu(&h, &self.norm);
        let mut frame = kernels::elementwise::zeros(self.out.cout() * side * side); // [3, 8s, 8s]
        self.out.forward(&pad, None, &mut frame);
        frame
    }

    /// `x + conv2(silu(norm2(conv1(silu(norm1(x))))))` on `[c, side, side]`.
    fn block(&self, b: &Block, x: Vec<f32>, side: usize) -> Vec<f32> {
        let c = b.conv1.cin();
        let mut pad = Padded::zeros(c, side, side);
        pad.fill_norm_silu(&x, &b.norm1);
        let mut t = kernels::elementwise::zeros(c * side * side);
        b.conv1.forward(&pad, None, &mut t);
        pad.fill_norm_silu(&t, &b.norm2);
        b.conv2.forward(&pad, Some(&x), &mut t);
        t
    }
}

#[cfg(test)]
mod tests {
    use burn::module::Param;
    use burn::nn::GroupNorm;
    use burn::tensor::{Device, Distribution, Tensor, TensorData};

    use super::*;
    use crate::autoencoder::AutoencoderConfig;

    #[test]
    fn decodes_what_burn_decodes() {
        // Random weights (GroupNorm's γ/β are 1/0 at init, so perturb them too, through a
        // trained-looking round: the check is that every layer is wired the same way).
        let device = Device::flex();
        let cfg = AutoencoderConfig {
            channels: [8, 16, 16, 16],
            latent_channels: 4,
            groups: 4,
            ..AutoencoderConfig::new()
        };
        let ae = cfg.init(&device);
        let ae = perturb_norms(ae);
        let z = Tensor::<4>::random([2, 4, 12, 12], Distribution::Normal(0.0, 1.0), &device);
        let want: Vec<f32> = ae.decode(z.clone()).into_data().try_to_vec().unwrap_or_default();
        let dec = CpuDecoder::new(&ae, 12).unwrap_or_else(|e| panic!("{e}"));
        let got = dec.decode(&z.into_data().try_to_vec::<f32>().unwrap_or_default(), 2);
        assert_eq!(got.len(), 2 * 3 * 96 * 96);
        let max = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        let scale = want.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
        assert!(scale > 1e-3, "degenerate test output");
        assert!(max < 1e-4 * scale.max(1.0), "max difference {max} (output scale {scale})");
    }

    /// A fixed amount of work for `perf stat -e task-clock` (CPU time, unaffected by other
    /// jobs): 40 frames through the default-size decoder.
    #[test]
    #[ignore = "a workload for profiling, not a check"]
    fn profile_workload() {
        let device = Device::flex();
        let ae = AutoencoderConfig::new().init(&device);
        let dec = CpuDecoder::new(&ae, 12).unwrap_or_else(|e| panic!("{e}"));
        let z: Vec<f32> = (0..40 * 8 * 144).map(|i| ((i * 7919) % 200) as f32 / 100.0 - 1.0).collect();
        assert_eq!(dec.decode(&z, 40).len(), 40 * 3 * 96 * 96);
    }

    /// Sets every GroupNorm's γ and β to non-trivial values.
    fn perturb_norms(mut ae: Autoencoder) -> Autoencoder {
        let device = Device::flex();
        let mut k = 0.0f32;
        let mut set = |n: &mut GroupNorm| {
            let c = n.num_channels;
            k += 1.0;
            let g: Vec<f32> = (0..c).map(|i| 0.5 + 0.1 * ((i as f32 + k) % 7.0)).collect();
            let b: Vec<f32> = (0..c).map(|i| 0.05 * ((i as f32 * 3.0 + k) % 5.0) - 0.1).collect();
            n.gamma = Some(Param::from_tensor(Tensor::from_data(TensorData::new(g, [c]), &device)));
            n.beta = Some(Param::from_tensor(Tensor::from_data(TensorData::new(b, [c]), &device)));
        };
        for b in &mut ae.dec_blocks {
            set(&mut b.norm1);
            set(&mut b.norm2);
        }
        set(&mut ae.dec_norm);
        ae
    }
}
