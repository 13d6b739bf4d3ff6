//! What the world model's "frames" are: autoencoder latents or raw pixels.
//!
//! DriftWorld exists in two families (spec §5): the latent family runs the U-Net
//! on a frame autoencoder's latents (the CPU default here, 96x96x3 -> 12x12x8),
//! the pixel family on the RGB frames themselves (the paper's Push-T model,
//! 96x96x3, 8.4M parameters — a GPU job). Everything downstream of the U-Net
//! (training windows, rollouts, scoring) only needs "encode frames to the model's
//! space" and "decode back", which this enum provides for both.

use std::path::Path;

use burn::tensor::{Device, Tensor};

use crate::autoencoder::Autoencoder;
use crate::error::WorldModelError;
use crate::train_ae::load_autoencoder;

/// The map between RGB frames in [-1, 1] and the space the U-Net works in.
#[derive(Clone, Debug)]
pub enum FrameCodec {
    /// A trained frame autoencoder (latent family).
    Latent {
        /// The autoencoder.
        ae: Box<Autoencoder>,
        /// Its input image side.
        image_size: usize,
        /// Latent channels C.
        channels: usize,
    },
    /// The frames themselves (pixel family): the identity map.
    Pixels {
        /// Image side.
        image_size: usize,
    },
}

impl FrameCodec {
    /// Loads the autoencoder in `dir` (from `train autoencoder`).
    ///
    /// # Errors
    /// [`WorldModelError::Checkpoint`] naming the autoencoder file at fault.
    pub fn autoencoder(dir: &Path, device: &Device) -> Result<Self, WorldModelError> {
        let (ae, cfg) = load_autoencoder(dir, device)?;
        Ok(Self::Latent { ae: Box::new(ae), image_size: cfg.image_size, channels: cfg.latent_channels })
    }

    /// Frames of `image_size` pixels as they are.
    pub fn pixels(image_size: usize) -> Self {
        Self::Pixels { image_size }
    }

    /// Whether this is the identity (pixel family).
    pub fn is_pixels(&self) -> bool {
        matches!(self, Self::Pixels { .. })
    }

    /// The RGB frames' side.
    pub fn image_size(&self) -> usize {
        match self {
            Self::Latent { image_size, .. } | Self::Pixels { image_size } => *image_size,
        }
    }

    /// Channels of one encoded frame (C for latents, 3 for pixels).
    pub fn channels(&self) -> usize {
        match self {
            Self::Latent { channels, .. } => *channels,
            Self::Pixels { .. } => 3,
        }
    }

    /// Side of one encoded frame (image / 8 for latents, the image for pixels).
    pub fn size(&self) -> usize {
        match self {
            Self::Latent { image_size, .. } => image_size / 8,
            Self::Pixels { image_size } => *image_size,
        }
    }

    /// Frames to the model's space (not normalised).
    ///
    /// # Shapes
    /// `[b, 3, H, W] -> [b, C, s, s]`
    pub fn encode(&self, frames: Tensor<4>) -> Tensor<4> {
        match self {
            Self::Latent { ae, .. } => ae.encode(frames),
            Self::Pixels { .. } => frames,
        }
    }

    /// The model's space back to frames (raw, nominally [-1, 1]).
    ///
    /// # Shapes
    /// `[b, C, s, s] -> [b, 3, H, W]`
    pub fn decode(&self, z: Tensor<4>) -> Tensor<4> {
        match self {
            Self::Latent { ae, .. } => ae.decode(z),
            Self::Pixels { .. } => z,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::autoencoder::AutoencoderConfig;

    #[test]
    fn pixels_are_the_identity_and_latents_are_an_eighth() {
        let device = Device::flex();
        let x = Tensor::<4>::random([2, 3, 16, 16], burn::tensor::Distribution::Default, &device);
        let p = FrameCodec::pixels(16);
        assert_eq!((p.channels(), p.size(), p.image_size()), (3, 16, 16));
        let back = p.decode(p.encode(x.clone()));
        assert_eq!(back.into_data(), x.clone().into_data());

        let cfg = AutoencoderConfig::new().with_image_size(16).with_latent_channels(4);
        let l = FrameCodec::Latent { ae: Box::new(cfg.init(&device)), image_size: 16, channels: 4 };
        assert_eq!((l.channels(), l.size()), (4, 2));
        assert_eq!(l.encode(x).dims(), [2, 4, 2, 2]);
    }
}
