//! Diffusion policies imported from other codebases (Chi et al.'s diffusion policy as they train
//! it): the `gpc-diffusion` kind (DriftWorld/GPC's Push-T policies, [`crate::import_gpc`]) and
//! the `lerobot-diffusion` kind (LeRobot's, [`crate::import_lerobot`]), one network family with
//! the few settings in which they differ.
//!
//! - Each of the last `obs_horizon` frames, in [0, 1] (LeRobot: then normalised by its image mean
//!   and std, and centre-cropped), goes through a ResNet-18 with GroupNorm or folded BatchNorms
//!   ([`ResNet18Gn`]) and
//!   either its global average pool (GPC: 512 features) or a spatial softmax over K keypoints, a
//!   linear layer and a ReLU (LeRobot: 2K features, [`SpatialHead`]). The conditioning is, per
//!   frame, oldest first, its features and the agent position min-max normalised to [-1, 1]
//!   (LeRobot: the position first).
//! - [`CondUnet1d`] (diffusion_policy's conditional 1-D U-Net, 1:1) predicts the noise of the
//!   `horizon`-step action sequence.
//! - Sampling is DDPM (diffusers' `DDPMScheduler`: squared-cosine betas, ε-prediction, x₀
//!   clipped to [-1, 1], "fixed small" variance) over every training step or over
//!   `inference_steps` of them with "leading" spacing, stochastic: the initial noise and each
//!   step's noise come from the episode's own generator, so a run is reproducible and
//!   independent of batching, not equal to PyTorch's draws. A LeRobot policy configured with
//!   `noise_scheduler_type: DDIM` samples with diffusers' `DDIMScheduler` instead (η = 0,
//!   ᾱ = 1 past the last step, x₀ clipped, the predicted noise kept): only the initial noise
//!   is drawn.
//! - Actions `obs_horizon − 1 ..` `+ action_horizon` of the sequence are executed.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::{relu, softmax};
use burn::tensor::{Device, Tensor, TensorData};
use harness::policy::{ActionChunk, Observation, Policy, PolicyError};
use harness::rng::Rng;

use crate::cpu_resnet::CpuResNet18;
use crate::cpu_unet::{CpuUnet1d, Prepared, Products};
use crate::diffusion::{Normalisation, alphas_cumprod, cpu_kernels_on, executed};
use crate::net::CondUnet1d;
use crate::resnet_gn::ResNet18Gn;

pub use crate::imported_config::{ImportedConfig, MeanStd, Pool, Prediction, Sampler};
pub use crate::imported_sampling::{
    bilinear_weights, centre_offset, ddim_sample, ddpm_sample, ddpm_step, resize_bilinear,
};

/// LeRobot's spatial softmax head: a 1×1 conv to K keypoint maps, a softmax over each map's
/// positions, the expected (x, y) on a grid spanning [-1, 1], then a linear layer and a ReLU.
#[derive(Module, Debug)]
pub struct SpatialHead {
    /// The 1×1 conv to the keypoint maps (with bias).
    pub nets: Conv2d,
    /// The linear layer after it.
    pub out: Linear,
}

impl SpatialHead {
    fn new(c: usize, k: usize, out: usize, device: &Device) -> Self {
        Self {
            nets: Conv2dConfig::new([c, k], [1, 1]).init(device),
            out: LinearConfig::new(2 * k, out).init(device),
        }
    }

    /// # Shapes
    /// `[n, c, h, w]` → `[n, out]` (from the x then y of each keypoint, keypoint by keypoint)
    fn forward(&self, x: Tensor<4>) -> Tensor<2> {
        let a = self.nets.forward(x); // [n, k, h, w]
        let [n, k, h, w] = a.dims();
        let a = softmax(a.reshape([n, k, h * w]), 2);
        // The grid: position i = (row, col) row-major, x = linspace(-1, 1, w)[col], y = linspace(-1, 1, h)[row].
        let lin = |m: usize, i: usize| if m > 1 { -1.0 + 2.0 * i as f64 / (m - 1) as f64 } else { 0.0 };
        let grid: Vec<f32> = (0..h * w).flat_map(|i| [lin(w, i % w) as f32, lin(h, i / w) as f32]).collect();
        let grid = Tensor::<2>::from_data(TensorData::new(grid, [h * w, 2]), &a.device());
        let kp = a.matmul(grid.unsqueeze::<3>().expand([n, h * w, 2])); // [n, k, 2]
        relu(self.out.forward(kp.reshape([n, 2 * k])))
    }
}

/// The networks of an imported policy.
#[derive(Module, Debug)]
pub struct ImportedNet {
    /// Frame encoder.
    pub encoder: ResNet18Gn,
    /// LeRobot's spatial-softmax head (none: the average pool).
    pub head: Option<SpatialHead>,
    /// Noise predictor.
    pub unet: CondUnet1d,
    /// Resize, centre crop, image normalisation and the order of each frame's conditioning.
    input_size: Option<usize>,
    antialias: bool,
    crop: Option<usize>,
    image_norm: Option<([f32; 3], [f32; 3])>,
    position_first: bool,
}

impl ImportedNet {
    /// Fresh networks of `cfg`'s sizes.
    pub fn new(cfg: &ImportedConfig, device: &Device) -> Self {
        let head = match cfg.pool {
            Pool::Average => None,
            Pool::SpatialSoftmax { keypoints, features } => Some(SpatialHead::new(
                8 * cfg.resnet_base,
                keypoints,
                features.unwrap_or(2 * keypoints),
                device,
            )),
        };
        Self {
            encoder: ResNet18Gn::new(cfg.resnet_base, cfg.backbone_norm, device),
            head,
            unet: CondUnet1d::new(&cfg.net, device),
            input_size: cfg.input_size,
            antialias: cfg.antialias,
            crop: cfg.crop,
            image_norm: cfg.image_norm.as_ref().map(|m| (m.mean, m.std)),
            position_first: cfg.position_first,
        }
    }

    /// Observation conditioning.
    ///
    /// # Shapes
    /// - `frames`: `[b·o, 3, h, w]` in [0, 1] (episode-major, oldest first)
    /// - `pos`: `[b, o, p]` normalised proprioception
    /// - returns `[b, o·(features + p)]`
    pub fn obs_cond(&self, frames: Tensor<4>, pos: Tensor<3>) -> Tensor<2> {
        self.obs_cond_on(frames, pos, None)
    }

    /// [`Self::obs_cond`] with the encoder's convolutions on `cpu` where given (its weights
    /// must be this network's encoder's).
    pub fn obs_cond_on(&self, frames: Tensor<4>, pos: Tensor<3>, cpu: Option<&CpuResNet18>) -> Tensor<2> {
        let [b, o, p] = pos.dims();
        let mut x = frames;
        if let Some((mean, std)) = &self.image_norm {
            let dev = x.device();
            let m = Tensor::<1>::from_floats(mean.as_slice(), &dev).reshape([1, 3, 1, 1]);
            let s = Tensor::<1>::from_floats(std.map(|v| v + 1e-8).as_slice(), &dev).reshape([1, 3, 1, 1]);
            x = (x - m) / s;
        }
        if let Some(r) = self.input_size {
            x = resize_bilinear(x, r, self.antialias);
        }
        if let Some(c) = self.crop {
            let [_, _, h, w] = x.dims();
            let (top, left) = (centre_offset(h.saturating_sub(c)), centre_offset(w.saturating_sub(c)));
            x = x.narrow(2, top, c.min(h)).narrow(3, left, c.min(w));
        }
        let input = |enc| Some((enc, x.clone().into_data().convert::<f32>().try_into_vec::<f32>().ok()?));
        let map = match cpu.and_then(input) {
            Some((enc, xs)) => {
                let [n, _, h, w] = x.dims();
                let (f, [c, fh, fw]) = enc.features(&xs, n, (h, w));
                Tensor::from_data(TensorData::new(f, [n, c, fh, fw]), &x.device())
            }
            None => self.encoder.features(x),
        };
        let feat = match &self.head {
            Some(head) => head.forward(map),
            None => self.encoder.pool(map),
        }; // [b o, f]
        let f = feat.dims()[1];
        let feat = feat.reshape([b, o, f]);
        let parts = if self.position_first { vec![pos, feat] } else { vec![feat, pos] };
        Tensor::cat(parts, 2).reshape([b, o * (f + p)])
    }
}

/// A loaded GPC policy (inference).
pub struct ImportedDiffusion {
    /// Checkpoint name.
    pub name: String,
    /// Configuration.
    pub cfg: ImportedConfig,
    /// Normalisation (recorded at import).
    pub norm: Normalisation,
    /// Each action entry's bounds in the task: outputs are clamped into them.
    pub bounds: (Vec<f32>, Vec<f32>),
    /// Where each of `cfg.robot_keys` lies in the task's robot state (offset, width): these
    /// entries, in this order, are the policy's proprioception (empty: the task's own).
    pub robot: Vec<(usize, usize)>,
    net: ImportedNet,
    /// The U-Net and the encoder on the project's CPU kernels (on the Flex device, unless
    /// [`crate::diffusion::POLICY_KERNELS_ENV`] says `burn`).
    cpu_unet: Option<CpuUnet1d>,
    cpu_encoder: Option<CpuResNet18>,
    ac: Vec<f64>,
    device: Device,
}

impl ImportedDiffusion {
    /// Wraps imported networks; `bounds` are the task's action bounds (low, high).
    pub fn new(
        name: String,
        cfg: ImportedConfig,
        norm: Normalisation,
        bounds: (Vec<f32>, Vec<f32>),
        net: ImportedNet,
        device: &Device,
    ) -> Self {
        let ac = alphas_cumprod(cfg.train_steps);
        let direct = cpu_kernels_on(device);
        // Imported policies have no recorded rows to keep: their products are the same bits on
        // every CPU, at AVX-512 speed where the CPU has it.
        let products = Products::or_env(Products::Chain);
        let cpu_unet = direct
            .then(|| {
                CpuUnet1d::new(&net.unet, products)
                    .inspect_err(|e| tracing::warn!(policy = %name, "burn's U-Net kept: {e}"))
            })
            .and_then(Result::ok);
        let cpu_encoder = direct
            .then(|| {
                CpuResNet18::new(&net.encoder, products)
                    .inspect_err(|e| tracing::warn!(policy = %name, "burn's encoder kept: {e}"))
            })
            .and_then(Result::ok);
        let robot = Vec::new();
        Self { name, cfg, norm, bounds, robot, net, cpu_unet, cpu_encoder, ac, device: device.clone() }
    }

    /// The observations with their proprioception made of the robot-state entries the policy
    /// reads ([`Self::robot`]).
    fn with_robot_state(&self, obs: &[Observation]) -> Result<Vec<Observation>, PolicyError> {
        let need = self.robot.iter().map(|(o, w)| o + w).max().unwrap_or(0);
        obs.iter()
            .enumerate()
            .map(|(i, ob)| {
                let proprio = ob
                    .robot
                    .iter()
                    .map(|r| {
                        if r.len() < need {
                            return Err(PolicyError::Input {
                                policy: self.name.clone(),
                                message: format!(
                                    "episode {i}: a robot state of {} entries, the policy reads {:?}",
                                    r.len(),
                                    self.cfg.robot_keys
                                ),
                            });
                        }
                        Ok(self.robot.iter().flat_map(|&(o, w)| r[o..o + w].iter().copied()).collect())
                    })
                    .collect::<Result<Vec<Vec<f32>>, _>>()?;
                Ok(Observation { proprio, ..ob.clone() })
            })
            .collect()
    }

    /// Every episode's last `obs_horizon` frames at the side the camera rendered them at, when
    /// that side is the one the policy resizes to ([`ImportedConfig::input_size`]) and every
    /// observation carries them ([`Observation::native`]; a simulator rendering at that side);
    /// `None` otherwise, and the scene's frames are resized.
    fn native_frames<'a>(&self, obs: &'a [Observation]) -> Option<(usize, Vec<&'a [u8]>)> {
        let (side, o) = (self.cfg.input_size?, self.cfg.net.obs_horizon);
        let mut out = Vec::with_capacity(obs.len() * o);
        for ob in obs {
            let native = ob.native.as_ref()?;
            let last = native.get(native.len().checked_sub(o)?..)?;
            if last.iter().any(|f| f.side != side || f.bytes.len() != side * side * 3) {
                return None;
            }
            out.extend(last.iter().map(|f| f.bytes.as_slice()));
        }
        Some((side, out))
    }

    /// The noise prediction for `x` (`[b, horizon, action_dim]`) at step `t` under `cond`
    /// (`prep`: its FiLM parts for the CPU U-Net, computed once a decision).
    fn eps(&self, (cond, prep): (&[f32], Option<&Prepared>), x: &[f32], b: usize, t: usize) -> Vec<f32> {
        self.cfg.prediction.noise(x, self.net_out((cond, prep), x, b, t), self.ac[t])
    }

    /// The U-Net's output for `x` (`[b, horizon, action_dim]`) at step `t` under `cond`.
    fn net_out(&self, (cond, prep): (&[f32], Option<&Prepared>), x: &[f32], b: usize, t: usize) -> Vec<f32> {
        let (h, ad) = (self.cfg.horizon, self.cfg.net.action_dim);
        if let Some((unet, prep)) = self.cpu_unet.as_ref().zip(prep) {
            return unet.forward(prep, x, h, t as f32);
        }
        let c = cond.len() / b.max(1);
        let cond = Tensor::from_data(TensorData::new(cond.to_vec(), [b, c]), &self.device);
        let x = Tensor::from_data(TensorData::new(x.to_vec(), [b, h, ad]), &self.device);
        let tt = Tensor::<1>::from_floats(vec![t as f32; b].as_slice(), &self.device);
        self.net
            .unet
            .forward(x, tt, cond)
            .into_data()
            .convert::<f32>()
            .try_into_vec::<f32>()
            .unwrap_or_default()
    }
}

impl Policy for ImportedDiffusion {
    fn name(&self) -> &str {
        &self.name
    }

    fn obs_horizon(&self) -> usize {
        self.cfg.net.obs_horizon
    }

    fn action_horizon(&self) -> usize {
        self.cfg.action_horizon
    }

    fn act(&self, obs: &[Observation], rngs: &mut [Rng]) -> Result<Vec<ActionChunk>, PolicyError> {
        let (o, s, h) = (self.cfg.net.obs_horizon, self.cfg.net.image_size, self.cfg.horizon);
        let (p, ad) = (self.norm.agent_pos.dim(), self.norm.action.dim());
        let selected;
        let obs = if self.robot.is_empty() {
            obs
        } else {
            selected = self.with_robot_state(obs)?;
            &selected[..]
        };
        let (frames, pos) = crate::diffusion::gather(&self.name, obs, o, s, p, &self.norm)?;
        let bad = |m: String| PolicyError::Input { policy: self.name.clone(), message: m };
        let b = obs.len();
        // Frames in [0, 1]: a world model's unrounded values where the run keeps them
        // (`rank --float-frames`, as the official loop feeds them), else the bytes.
        let exact: Option<Vec<&[f32]>> = obs
            .iter()
            .map(|ob| ob.exact.as_ref().map(|e| e.iter().map(Vec::as_slice).collect::<Vec<_>>()))
            .collect::<Option<Vec<_>>>()
            .map(|v| v.into_iter().flatten().collect());
        let x01 = match exact.filter(|e| e.len() == frames.len() && e.iter().all(|f| f.len() == s * s * 3)) {
            Some(e) => nn::frames::unit_floats_to_tensor(&e, s, &self.device),
            None => {
                // The camera's own frames at the policy's size (`[visual] render_size`): what
                // the policy was trained on, where resizing the scene's frames back would not be.
                let (side, bytes) = self.native_frames(obs).unwrap_or((s, frames));
                nn::frames::frames_to_tensor(&bytes, side, &self.device) * 0.5 + 0.5
            }
        };
        let pos = Tensor::from_data(TensorData::new(pos, [b, o, p]), &self.device);
        let cond = self
            .net
            .obs_cond_on(x01, pos, self.cpu_encoder.as_ref())
            .into_data()
            .convert::<f32>()
            .try_into_vec::<f32>()
            .unwrap_or_default();
        // What the observations give every FiLM layer of the CPU U-Net: the same for all steps.
        let prep = self.cpu_unet.as_ref().map(|u| u.prepare(&cond, b));
        let cond = (cond.as_slice(), prep.as_ref());
        // Each episode's initial noise, then each step's, from its own generator.
        let x: Vec<f32> = rngs.iter_mut().flat_map(|r| r.normals_f32(h * ad)).collect();
        let per = h * ad;
        let v = match self.cfg.sampler {
            Sampler::Ddpm => ddpm_sample(
                x,
                &self.ac,
                &self.cfg.timesteps(),
                |x, t| self.eps(cond, x, b, t),
                |_| rngs.iter_mut().flat_map(|r| r.normals_f32(per)).collect(),
            ),
            Sampler::Ddim => ddim_sample(x, &self.ac, &self.cfg.timesteps(), |x, t| self.eps(cond, x, b, t)),
        };
        if v.len() != b * h * ad || v.iter().any(|x| !x.is_finite()) {
            return Err(bad(format!(
                "the network returned {} values (finite?), expected {}",
                v.len(),
                b * h * ad
            )));
        }
        executed(&self.name, &v, [b, h, ad], o - 1, self.cfg.action_horizon, &self.norm, &self.bounds)
    }
}

/// Loads a `gpc-diffusion` checkpoint folder (`policy.json` + `model.bpk`), checked against
/// what the scenario gives.
///
/// # Errors
/// [`PolicyLoadError`] naming the folder for a config that does not fit the scenario or
/// weights that are missing, truncated or do not match it.
pub fn load(
    dir: &std::path::Path,
    file: crate::dir::PolicyFile,
    expect: &crate::dir::Expectations,
    device: &Device,
) -> Result<Box<dyn Policy>, crate::dir::PolicyLoadError> {
    load_returning(dir, file, expect, device, None)
}

/// [`load`], the policy returning `returns` actions a decision instead of its own action
/// horizon (`plan` imagines and executes slices of other lengths; the policy still predicts
/// its whole horizon). `returns` must fit ([`ImportedConfig::max_action_horizon`]).
///
/// # Errors
/// As [`load`], and a `returns` that does not fit.
pub fn load_returning(
    dir: &std::path::Path,
    file: crate::dir::PolicyFile,
    expect: &crate::dir::Expectations,
    device: &Device,
    returns: Option<usize>,
) -> Result<Box<dyn Policy>, crate::dir::PolicyLoadError> {
    let err = |m: String| crate::dir::PolicyLoadError::new(dir, m);
    let mut cfg: ImportedConfig = serde_json::from_value(file.config.clone())
        .map_err(|e| err(format!("policy.json \"config\": {e}")))?;
    if let Some(r) = returns {
        cfg.action_horizon = r;
    }
    let n = &cfg.net;
    if n.image_size != expect.image_size {
        return Err(err(format!(
            "takes {0}x{0} frames, the scenario renders {1}x{1}",
            n.image_size, expect.image_size
        )));
    }
    let robot = if cfg.robot_keys.is_empty() {
        Vec::new()
    } else {
        harness::task::robot_slices(&expect.robot, &cfg.robot_keys).map_err(|e| err(e.to_string()))?
    };
    let reads = if robot.is_empty() { expect.proprio_dim } else { robot.iter().map(|(_, w)| w).sum() };
    if n.action_dim != expect.action_dim() || n.proprio() != reads {
        return Err(err(format!(
            "acts in {}-D and reads {} proprioceptive entries, the scenario takes {}-D and gives {}",
            n.action_dim,
            n.proprio(),
            expect.action_dim(),
            reads
        )));
    }
    let norm = &file.normalisation;
    if norm.agent_pos.dim() != n.proprio() || norm.action.dim() != n.action_dim {
        return Err(err("policy.json \"normalisation\" does not fit the config".into()));
    }
    if cfg.action_horizon == 0 || cfg.action_horizon > cfg.max_action_horizon() || cfg.train_steps == 0 {
        return Err(err(format!(
            "action horizon {} does not fit horizon {}",
            cfg.action_horizon, cfg.horizon
        )));
    }
    let net = crate::dir::load_weights(ImportedNet::new(&cfg, device), &dir.join("model.bpk"))
        .map_err(|e| err(format!("model.bpk: {e}")))?;
    let bounds = (expect.action_low.clone(), expect.action_high.clone());
    let name = crate::dir::checkpoint_name(dir);
    let mut policy = ImportedDiffusion::new(name, cfg, file.normalisation, bounds, net, device);
    policy.robot = robot;
    Ok(Box::new(policy))
}

/// The U-Net's output for `x` (`dims` = `[b, horizon, action_dim]`) at step `t` under `cond`
/// (`[b, c]`), through burn: what the importers' tests compare with PyTorch.
#[cfg(test)]
pub(crate) fn unet_out(net: &ImportedNet, cond: &[f32], x: &[f32], dims: [usize; 3], t: usize) -> Vec<f32> {
    let device = Device::flex();
    let xt = Tensor::from_data(TensorData::new(x.to_vec(), dims), &device);
    let ct = Tensor::from_data(TensorData::new(cond.to_vec(), [dims[0], cond.len() / dims[0]]), &device);
    let tt = Tensor::<1>::from_floats(vec![t as f32; dims[0]].as_slice(), &device);
    net.unet.forward(xt, tt, ct).into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default()
}

/// Hands out `noises` in order, `n` values a call: a PyTorch run's step noise, replayed.
#[cfg(test)]
pub(crate) fn replayed(noises: Vec<f32>) -> impl FnMut(usize) -> Vec<f32> {
    let mut at = 0;
    move |n| {
        at += n;
        noises[at - n..at].to_vec()
    }
}

#[cfg(test)]
#[path = "imported_policy_tests.rs"]
mod tests;
