//! Vision policies for Push-T, trained on the project's own demonstrations.
//!
//! - [`net`]: the CNN frame encoder and the conditional 1-D U-Net;
//! - [`cpu_unet`], [`cpu_encoder`], [`cpu_resnet`]: the U-Net, the encoder and the imported
//!   policies' ResNet-18 on the project's own CPU kernels, which inference uses on the Flex device;
//! - [`diffusion`]: the `diffusion` kind (DDPM training, DDIM inference) behind
//!   [`harness::policy::Policy`];
//! - [`data`]: demonstrations from a replay-buffer dataset;
//! - [`pretrain`]: pose pre-training of the frame encoder and the frozen-feature cache;
//! - [`symmetry`]: the 8 symmetries of Push-T's square world, exact augmentations;
//! - [`train`]: the trainer, which saves a checkpoint every few epochs;
//! - [`dir`]: the policy directory format and its validating loader; [`kinds`]: a checkpoint
//!   of any kind loaded for a task (a `scripted` one by the task itself);
//! - [`provenance`]: how a checkpoint was made and what it scored, typed;
//! - [`imported_policy`], [`import_gpc`], [`import_lerobot`], [`resnet_gn`]: diffusion policies
//!   trained elsewhere (DriftWorld/GPC's Push-T policies, LeRobot's), imported once: the
//!   `gpc-diffusion` and `lerobot-diffusion` kinds, DDPM sampling;
//! - [`resnet`]: torchvision's ResNet-18 with BatchNorms folded, which GPC's reward
//!   predictors use (imported as a judge by the `judges` crate, which also builds its learned
//!   judges on [`net`]'s frame encoder).

pub mod adapt;
pub mod adapt_decision;
pub mod cpu_encoder;
pub mod cpu_resnet;
pub mod cpu_unet;
pub mod data;
pub mod diffusion;
pub mod dir;
pub mod gpc_stats;
pub mod import_gpc;
mod import_keys;
pub mod import_lerobot;
pub mod import_robomimic;
pub mod imported_config;
pub mod imported_policy;
pub mod imported_sampling;
pub mod kinds;
mod lerobot_config;
pub mod net;
pub mod pose_probe;
pub mod pretrain;
pub mod provenance;
pub mod resnet;
pub mod resnet_gn;
mod robomimic_config;
mod robomimic_weights;
pub mod symmetry;
pub mod train;
mod train_config;
mod train_parts;
