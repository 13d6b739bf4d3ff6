//! Frame autoencoder: 96x96 RGB frames <-> 12x12xC latents.
//!
//! DriftWorld's latent family runs the drifting U-Net on autoencoder latents; on
//! a CPU this is what makes training feasible (a 96x96 pixel-space U-Net step is
//! ~50 s here). Three stride-2 convolutions take 96 -> 12; GroupNorm + SiLU
//! residual blocks in between; the decoder mirrors it with nearest-neighbour
//! upsampling and a residual block at full resolution to keep edges sharp.

use burn::config::Config;
use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::nn::interpolate::{Interpolate2d, Interpolate2dConfig, InterpolateMode};
use burn::nn::{GroupNorm, GroupNormConfig};
use burn::tensor::activation::silu;
use burn::tensor::{Device, Tensor};
use nn::layers::conv;

/// Autoencoder hyper-parameters.
#[derive(Config, Debug, PartialEq)]
pub struct AutoencoderConfig {
    /// Image side (frames are square).
    #[config(default = 96)]
    pub image_size: usize,
    /// Channels at 96, 48, 24 and 12 pixels.
    #[config(default = "[16, 32, 64, 64]")]
    pub channels: [usize; 4],
    /// Latent channels C (the latent is C x image/8 x image/8).
    #[config(default = 8)]
    pub latent_channels: usize,
    /// GroupNorm groups.
    #[config(default = 8)]
    pub groups: usize,
    /// The decoder's channels at 96, 48, 24 and 12 pixels (listed like `channels`);
    /// `None`: the same as the encoder's. A narrower decoder
    /// is cheaper per decoded frame, which is most of `rank`'s world-model time.
    #[config(default = "None")]
    pub decoder_channels: Option<[usize; 4]>,
}

impl AutoencoderConfig {
    /// Whether `other` has the same encoder (image size, encoder channels, latent
    /// channels, groups), so that its encoder's weights fit this config.
    pub fn same_encoder(&self, other: &AutoencoderConfig) -> bool {
        (self.image_size, self.channels, self.latent_channels, self.groups)
            == (other.image_size, other.channels, other.latent_channels, other.groups)
    }

    /// Latent side (image / 8).
    pub fn latent_size(&self) -> usize {
        self.image_size / 8
    }

    /// Builds the module.
    pub fn init(&self, device: &Device) -> Autoencoder {
        let [e0, e1, e2, e3] = self.channels;
        let [c0, c1, c2, c3] = self.decoder_channels.unwrap_or(self.channels);
        let g = self.groups;
        let up = || {
            Interpolate2dConfig::new()
                .with_scale_factor(Some([2.0, 2.0]))
                .with_mode(InterpolateMode::Nearest)
                .init()
        };
        Autoencoder {
            enc_in: conv(3, e0, 3, 1, device),
            enc_down: vec![
                conv(e0, e1, 3, 2, device),
                conv(e1, e2, 3, 2, device),
                conv(e2, e3, 3, 2, device),
            ],
            enc_blocks: vec![
                ResBlock::new(e1, g, device),
                ResBlock::new(e2, g, device),
                ResBlock::new(e3, g, device),
            ],
            enc_norm: GroupNormConfig::new(g, e3).init(device),
            enc_out: conv(e3, self.latent_channels, 1, 1, device),
            dec_in: conv(self.latent_channels, c3, 3, 1, device),
            dec_blocks: vec![
                ResBlock::new(c3, g, device),
                ResBlock::new(c2, g, device),
                ResBlock::new(c1, g, device),
                ResBlock::new(c0, g, device),
            ],
            dec_up: vec![conv(c3, c2, 3, 1, device), conv(c2, c1, 3, 1, device), conv(c1, c0, 3, 1, device)],
            upsample: up(),
            dec_norm: GroupNormConfig::new(g, c0).init(device),
            dec_out: conv(c0, 3, 3, 1, device),
        }
    }
}

/// GroupNorm -> SiLU -> conv, twice, plus the input.
#[derive(Module, Debug)]
pub struct ResBlock {
    pub(crate) norm1: GroupNorm,
    pub(crate) conv1: Conv2d,
    pub(crate) norm2: GroupNorm,
    pub(crate) conv2: Conv2d,
}

impl ResBlock {
    fn new(c: usize, groups: usize, device: &Device) -> Self {
        Self {
            norm1: GroupNormConfig::new(groups, c).init(device),
            conv1: conv(c, c, 3, 1, device),
            norm2: GroupNormConfig::new(groups, c).init(device),
            conv2: conv(c, c, 3, 1, device),
        }
    }

    /// # Shapes
    /// `[b, c, h, w] -> [b, c, h, w]`
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let h = self.conv1.forward(silu(self.norm1.forward(x.clone())));
        let h = self.conv2.forward(silu(self.norm2.forward(h)));
        x + h
    }
}

/// The frame autoencoder.
#[derive(Module, Debug)]
pub struct Autoencoder {
    enc_in: Conv2d,
    enc_down: Vec<Conv2d>,
    enc_blocks: Vec<ResBlock>,
    enc_norm: GroupNorm,
    enc_out: Conv2d,
    pub(crate) dec_in: Conv2d,
    pub(crate) dec_blocks: Vec<ResBlock>,
    pub(crate) dec_up: Vec<Conv2d>,
    upsample: Interpolate2d,
    pub(crate) dec_norm: GroupNorm,
    pub(crate) dec_out: Conv2d,
}

impl Autoencoder {
    /// Frames in [-1, 1] to latents.
    ///
    /// # Shapes
    /// `[b, 3, 96, 96] -> [b, C, 12, 12]`
    pub fn encode(&self, x: Tensor<4>) -> Tensor<4> {
        let mut h = self.enc_in.forward(x); // [b, c0, 96, 96]
        for (down, block) in self.enc_down.iter().zip(&self.enc_blocks) {
            h = block.forward(down.forward(h)); // [b, c1, 48, 48], [b, c2, 24, 24], [b, c3, 12, 12]
        }
        self.enc_out.forward(silu(self.enc_norm.forward(h))) // [b, C, 12, 12]
    }

    /// Latents to frames (raw, nominally in [-1, 1]).
    ///
    /// # Shapes
    /// `[b, C, 12, 12] -> [b, 3, 96, 96]`
    pub fn decode(&self, z: Tensor<4>) -> Tensor<4> {
        let mut h = self.dec_blocks[0].forward(self.dec_in.forward(z)); // [b, c3, 12, 12]
        for (up, block) in self.dec_up.iter().zip(&self.dec_blocks[1..]) {
            h = block.forward(up.forward(self.upsample.forward(h))); // 24, 48, 96
        }
        self.dec_out.forward(silu(self.dec_norm.forward(h))) // [b, 3, 96, 96]
    }

    /// This model with `other`'s encoder (its weights, moved over), for training a new
    /// decoder on the latents of an existing autoencoder (`train autoencoder
    /// --encoder-from`). The two configs must agree on the encoder (checked by the
    /// caller with [`AutoencoderConfig::same_encoder`]).
    pub fn with_encoder_of(self, other: Autoencoder) -> Self {
        Self {
            enc_in: other.enc_in,
            enc_down: other.enc_down,
            enc_blocks: other.enc_blocks,
            enc_norm: other.enc_norm,
            enc_out: other.enc_out,
            ..self
        }
    }

    /// Whether `other` encodes exactly as this model does: both encode the same
    /// fixed, frame-like input to the same latents, bit for bit (identical encoder
    /// weights do; a retrained encoder does not). Latents of one are then latents
    /// of the other, so a world model trained on them may decode with either.
    pub fn encodes_like(&self, other: &Autoencoder, device: &Device) -> bool {
        let x = nn::frames::probe_frames(2, 32, device); // [2, 3, 32, 32]
        let (a, b) = (self.encode(x.clone()).into_data(), other.encode(x).into_data());
        a.shape() == b.shape() && a.as_slice::<f32>().ok() == b.as_slice::<f32>().ok()
    }

    /// Encode then decode.
    ///
    /// # Shapes
    /// `[b, 3, 96, 96] -> [b, 3, 96, 96]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        self.decode(self.encode(x))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_copied_encoder_encodes_alike_and_a_narrow_decoder_decodes() {
        let device = Device::flex();
        device.seed(3);
        let source = AutoencoderConfig::new().init(&device);
        let narrow =
            AutoencoderConfig { decoder_channels: Some([8, 16, 32, 32]), ..AutoencoderConfig::new() };
        assert!(narrow.same_encoder(&AutoencoderConfig::new()));
        assert!(!narrow.same_encoder(&AutoencoderConfig::new().with_latent_channels(4)));
        let fresh = narrow.init(&device);
        assert!(!fresh.encodes_like(&source, &device), "independent draws encode differently");
        let copied = fresh.with_encoder_of(source.clone());
        assert!(copied.encodes_like(&source, &device));
        let z = copied.encode(Tensor::<4>::zeros([1, 3, 96, 96], &device));
        assert_eq!(copied.decode(z).dims(), [1, 3, 96, 96]);
    }

    #[test]
    fn shapes_round_trip() {
        let device = Device::flex();
        let cfg = AutoencoderConfig::new();
        let ae = cfg.init(&device);
        let x = Tensor::<4>::zeros([2, 3, 96, 96], &device);
        let z = ae.encode(x);
        assert_eq!(z.dims(), [2, 8, 12, 12]);
        assert_eq!(ae.decode(z).dims(), [2, 3, 96, 96]);
    }
}
