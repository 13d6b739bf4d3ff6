//! The U-Net's hyper-parameters ([`UNetConfig`]), stored in a world model's `config.json`, and
//! what follows from them: the checks a configuration must pass and the settings the blocks are
//! built with.

use burn::config::Config;

use crate::error::SettingError;

/// U-Net hyper-parameters.
#[derive(Config, Debug, PartialEq)]
pub struct UNetConfig {
    /// Channels of one frame (3 in pixel space, C in latent space).
    pub frame_channels: usize,
    /// Context frames K.
    #[config(default = 4)]
    pub history: usize,
    /// Base channels.
    pub model_channels: usize,
    /// Channel multiplier per level.
    pub channel_mult: Vec<usize>,
    /// Residual blocks per level (the decoder has one more).
    #[config(default = 2)]
    pub res_blocks: usize,
    /// Downsampling rates (1, 2, 4, ...) whose levels get spatial attention.
    pub attention_rates: Vec<usize>,
    /// Channels per attention head.
    #[config(default = 8)]
    pub head_dim: usize,
    /// GroupNorm groups.
    #[config(default = 32)]
    pub groups: usize,
    /// Action dimension.
    #[config(default = 2)]
    pub action_dim: usize,
    /// Action (and timestep) embedding size.
    #[config(default = 256)]
    pub emb_dim: usize,
    /// Add a diffusion timestep embedding (the multi-step baseline).
    #[config(default = false)]
    pub timestep_embedding: bool,
    /// Feed each future frame's action as a Gaussian map at its position too
    /// (one more input channel; not in the paper). An option so that configs
    /// written before it existed still load (missing = none).
    #[config(default = "None")]
    pub action_maps: Option<bool>,
    /// Feed the episode's first observed frame (the anchor) as C more input
    /// channels (not in the paper). An option for the same reason (missing = no).
    #[config(default = "None")]
    pub anchor: Option<bool>,
    /// Read an action-accentuation strength α (spec §3, [`accent`]). An option for
    /// the same reason (missing = no).
    #[config(default = "None")]
    pub accentuation: Option<bool>,
    /// GroupNorm statistics of the attention blocks taken per frame, as the official
    /// DriftWorld code does (its models imported by `evalharness import`), instead of over
    /// the whole clip as evalharness's own models do. An option for the same reason
    /// (missing = the whole clip).
    #[config(default = "None")]
    pub frame_attention_norm: Option<bool>,
}

impl UNetConfig {
    /// Whether the U-Net reads action maps.
    pub fn uses_action_maps(&self) -> bool {
        self.action_maps == Some(true)
    }

    /// Whether the U-Net reads the anchor frame.
    pub fn uses_anchor(&self) -> bool {
        self.anchor == Some(true)
    }

    /// Whether the U-Net reads an accentuation strength α.
    pub fn uses_accentuation(&self) -> bool {
        self.accentuation == Some(true)
    }

    /// Whether the attention blocks normalise each frame alone
    /// ([`UNetConfig::frame_attention_norm`]).
    pub fn frame_attention_norm(&self) -> bool {
        self.frame_attention_norm == Some(true)
    }

    /// Whether a run with this config can start from `source`'s weights: the same
    /// U-Net, or one that lacks only action maps, the anchor and/or the timestep
    /// embedding (added with zero weights by [`UNet::with_action_maps`],
    /// [`UNet::with_anchor`] and [`UNet::with_timestep_embedding`], so the
    /// warm-started network computes exactly what its source did).
    pub fn can_start_from(&self, source: &UNetConfig) -> bool {
        let mut bridged = source.clone();
        if self.uses_action_maps() {
            bridged.action_maps = Some(true);
        }
        if self.uses_anchor() {
            bridged.anchor = Some(true);
        }
        if self.uses_accentuation() {
            bridged.accentuation = Some(true);
        }
        bridged.timestep_embedding |= self.timestep_embedding;
        bridged == *self // bridging only adds what `self` has, so the same config passes
    }

    /// The paper's pixel-space Push-T model: 96x96 RGB, 96 channels, 4 levels,
    /// attention at 24² and 12² (8,375,201 parameters).
    pub fn pusht_pixel() -> Self {
        Self::new(3, 96, vec![1, 1, 1, 1], vec![4, 8])
    }

    /// The CPU default: on 12x12x8 autoencoder latents, 2 levels (12², 6²).
    pub fn pusht_latent(latent_channels: usize) -> Self {
        Self::new(latent_channels, 64, vec![1, 2], vec![2]).with_groups(16)
    }

    /// Whether a U-Net can be built from these numbers: every size positive, every level's
    /// channels (`model_channels` × its multiplier) divisible by the GroupNorm groups, and
    /// those of every level with attention (and the middle block's) by the head width.
    /// burn asserts the same inside `init` (a panic); this says which setting is wrong.
    ///
    /// # Errors
    /// The first setting that does not fit, by its config name.
    pub fn check(&self) -> Result<(), SettingError> {
        let sizes = [
            ("frame_channels", self.frame_channels),
            ("model_channels", self.model_channels),
            ("res_blocks", self.res_blocks),
            ("head_dim", self.head_dim),
            ("groups", self.groups),
            ("action_dim", self.action_dim),
            ("emb_dim", self.emb_dim),
        ];
        if let Some(&(name, _)) = sizes.iter().find(|(_, v)| *v == 0) {
            return Err(SettingError::Zero { name });
        }
        if self.channel_mult.is_empty() || self.channel_mult.contains(&0) {
            return Err(SettingError::ChannelMult { mult: self.channel_mult.clone() });
        }
        let (mc, g, h) = (self.model_channels, self.groups, self.head_dim);
        let deepest = mc * self.channel_mult.last().copied().unwrap_or(1);
        for (l, m) in self.channel_mult.iter().enumerate() {
            let c = m * mc;
            if c % g != 0 || mc % g != 0 {
                return Err(SettingError::Groups { base: mc, mult: *m, channels: c, level: l, groups: g });
            }
            let attended = self.attention_rates.contains(&(1 << l)) || c == deepest;
            if attended && c % h != 0 {
                return Err(SettingError::Heads { channels: c, level: l, head_dim: h });
            }
        }
        Ok(())
    }
}
