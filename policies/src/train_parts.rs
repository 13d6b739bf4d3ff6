//! The policy trainer's parts, apart from its loop (`train::train_policy`): the network,
//! optimiser, EMA and step counter a run starts or resumes with, their checkpoint, the
//! frozen encoder's cached features, one batch's loss, and an epoch's policy checkpoint.

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::optim::{AdamWConfig, ModuleOptimizer};
use burn::tensor::{Device, Tensor, TensorData};
use harness::driver::Clock;
use harness::rng::Rng;
use harness::seed::derive;
use serde::{Deserialize, Serialize};

use crate::data::Demos;
use crate::diffusion::{DiffusionConfig, DiffusionNet, frames_to_tensor};
use crate::dir::{
    PolicyFile, PolicyLoadError, diffusion_config, diffusion_weights, read_policy_file, write_policy,
};
use crate::pretrain::{Pretrain, encode_frames, pretrain_encoder};
use crate::provenance::{EncoderPretraining, PolicyProvenance, RawWeights, Weights};
use crate::train_config::{Phase, PolicyProgress, PolicyRun, RunConfigs};
use nn::optim::Ema;

/// The resumable step counter.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub(crate) struct State {
    pub(crate) step: u64,
    pub(crate) elapsed_s: f64,
    /// EMA updates so far (they start when `ema` is first set, possibly mid-run).
    #[serde(default)]
    pub(crate) ema_updates: u64,
}

/// What a run trains and where it stands.
pub(crate) struct Training {
    pub(crate) net: DiffusionNet,
    pub(crate) optim: ModuleOptimizer,
    pub(crate) ema: Ema<DiffusionNet>,
    pub(crate) state: State,
}

/// The checkpoint's files in `.train/`.
const FILES: [&str; 4] = ["model.bpk", "optimizer.bpk", "state.json", "ema.bpk"];

impl Training {
    /// Fresh weights (or the starting checkpoint's), or on `run.resume` the committed
    /// checkpoint in `dir` (recovered first if a save was torn).
    pub(crate) fn start(
        dir: &Path,
        configs: &RunConfigs,
        run: &PolicyRun,
        device: &Device,
    ) -> Result<Self, PolicyLoadError> {
        let (pc, tc) = (&configs.policy, &configs.train);
        let paths = FILES.map(|p| dir.join(p));
        // The fresh weights are a function of the seed (a run's bytes follow from its
        // command; before 2026-12-03 they were drawn unseeded and two runs differed).
        device.seed(derive(tc.seed, &[u64::MAX - 2]));
        let mut net = DiffusionNet::new(pc, device);
        let mut optim = AdamWConfig::new()
            .with_beta_1(0.95)
            .with_beta_2(0.999)
            .with_weight_decay(tc.weight_decay as f32)
            .init();
        let mut state = State::default();
        if run.resume {
            harness::checkpoint::recover(dir, harness::checkpoint::MAIN)?;
            net = net.try_load_file(&paths[0]).map_err(|e| PolicyLoadError::new(&paths[0], e.to_string()))?;
            optim = optim.load(&paths[1]).map_err(|e| PolicyLoadError::new(&paths[1], e.to_string()))?;
            state = harness::driver::read_state(&paths[2])?;
        }
        if let Some(src) = tc.init_from.as_ref().filter(|_| !run.resume) {
            net = init_weights(src, pc, device)?;
        }
        let mut ema = Ema::new(&net, tc.ema);
        if tc.ema > 0.0 && state.ema_updates > 0 {
            let module = ema.module.clone();
            ema.module = module
                .try_load_file(&paths[3])
                .map_err(|e| PolicyLoadError::new(&paths[3], e.to_string()))?;
        }
        Ok(Self { net, optim, ema, state })
    }

    /// Saves the weights, optimiser, step counter and (after its first update) the EMA as
    /// one checkpoint in `dir`: staged, then committed by a manifest.
    pub(crate) fn save(&self, dir: &Path) -> Result<(), PolicyLoadError> {
        let mut stage = harness::checkpoint::begin(dir, harness::checkpoint::MAIN)?;
        let p = [FILES[0], FILES[1], FILES[2]].map(|n| stage.path(n));
        self.net.clone().save_file(&p[0]).map_err(|e| PolicyLoadError::new(&p[0], e.to_string()))?;
        self.optim.save(&p[1]).map_err(|e| PolicyLoadError::new(&p[1], e.to_string()))?;
        // The manifest lists only what this checkpoint has (no EMA before its first update).
        if self.state.ema_updates > 0 {
            let e = stage.path(FILES[3]);
            self.ema.module.clone().save_file(&e).map_err(|err| PolicyLoadError::new(&e, err.to_string()))?;
        }
        harness::driver::write_state(&p[2], &self.state)?;
        Ok(stage.commit()?)
    }
}

/// The frames' conditioning source for the U-Net.
pub(crate) enum Features {
    /// Encoder and U-Net train end to end on the frames.
    EndToEnd,
    /// A frozen encoder's features of every frame, `[frames, feature_dim]` row-major.
    Cached(Vec<f32>),
    /// The clock ran out during the encoder's pre-training.
    Stopped,
}

/// The frozen encoder's features: pre-trained first when the run asks for it (its result
/// recorded in `provenance`, and installed in a run that has not stepped yet), else the
/// starting checkpoint's encoder, else none (end to end).
#[allow(clippy::too_many_arguments)]
pub(crate) fn features(
    demos: &Demos,
    configs: &RunConfigs,
    training: &mut Training,
    provenance: &mut PolicyProvenance,
    (dir, clock): (&Path, Clock),
    inner: &Device,
    on_progress: &mut dyn FnMut(&PolicyProgress),
) -> Result<Features, PolicyLoadError> {
    let (pc, tc) = (&configs.policy, &configs.train);
    let s = pc.net.image_size;
    if tc.encoder_steps > 0 {
        let p = Pretrain { steps: tc.encoder_steps, lr: tc.encoder_lr, seed: tc.seed };
        let enc_total = tc.encoder_steps;
        let (ps, probe) = pretrain_encoder(demos, &pc.net, p, dir, clock, inner, &mut |step, loss| {
            on_progress(&PolicyProgress { phase: Phase::Encoder, step, total: enc_total, epoch: 0, loss });
        })?;
        let Some(probe) = probe else { return Ok(Features::Stopped) };
        provenance.encoder_pretraining = Some(EncoderPretraining {
            heldout_mean_abs_error: ps.heldout_columns.clone(),
            heldout_pose_error: ps.heldout,
            steps: ps.step,
        });
        if training.state.step == 0 {
            training.net.encoder = probe.encoder;
            training.ema = Ema::new(&training.net, tc.ema);
        }
        tracing::info!(frames = demos.len(), "encoding every frame with the frozen encoder");
        Ok(Features::Cached(encode_frames(&training.net.encoder.valid(), demos, s, inner)))
    } else if tc.init_from.is_some() {
        // The starting checkpoint's encoder (saved unchanged in `.train/model.bpk` on resume).
        tracing::info!(frames = demos.len(), "encoding every frame with the starting checkpoint's encoder");
        Ok(Features::Cached(encode_frames(&training.net.encoder.valid(), demos, s, inner)))
    } else {
        Ok(Features::EndToEnd)
    }
}

/// The diffusion loss of one batch of sample indices at training step `step`: each sample's
/// `obs_horizon` observations (oldest first) and `horizon` actions, normalised; timesteps and
/// noise drawn from (seed, step).
pub(crate) fn batch_loss(
    net: &DiffusionNet,
    demos: &Demos,
    configs: &RunConfigs,
    (batch, step): (&[usize], u64),
    features: &Features,
    ac: &[f64],
    device: &Device,
) -> Tensor<1> {
    let (pc, tc) = (&configs.policy, &configs.train);
    let (o, h, s) = (pc.net.obs_horizon, pc.horizon, pc.net.image_size);
    let (pd, ad) = (demos.proprio_dim, demos.action_dim);
    let b = batch.len();
    let mut obs = Vec::with_capacity(b * o);
    let (mut pos, mut act) = (Vec::with_capacity(b * o * pd), Vec::with_capacity(b * h * ad));
    for &t in batch {
        let (oi, ai) = demos.sample_indices(t, o, h);
        obs.extend_from_slice(&oi);
        pos.extend(oi.iter().flat_map(|&i| configs.normalisation.agent_pos.normalise(demos.proprio_at(i))));
        act.extend(ai.iter().flat_map(|&i| configs.normalisation.action.normalise(demos.action_at(i))));
    }
    let mut rng = Rng::new(derive(tc.seed, &[u64::MAX, step]));
    let t: Vec<usize> = (0..b).map(|_| rng.below(pc.train_steps as u64) as usize).collect();
    let noise = Tensor::from_data(TensorData::new(rng.normals_f32(b * h * ad), [b, h, ad]), device);
    let cond = match features {
        // Frozen encoder: [b, o·(f + pd)] from the cache, no gradient reaches the encoder.
        Features::Cached(cache) => {
            let f = pc.net.feature_dim;
            let mut c = Vec::with_capacity(b * o * (f + pd));
            for (j, &i) in obs.iter().enumerate() {
                c.extend_from_slice(&cache[i * f..(i + 1) * f]);
                c.extend_from_slice(&pos[j * pd..(j + 1) * pd]);
            }
            Tensor::from_data(TensorData::new(c, [b, o * (f + pd)]), device)
        }
        Features::EndToEnd | Features::Stopped => {
            let frames: Vec<&[u8]> = obs.iter().map(|&i| demos.frame(i)).collect();
            net.obs_cond(
                frames_to_tensor(&frames, s, device),
                Tensor::from_data(TensorData::new(pos, [b, o, pd]), device),
            )
        }
    };
    let actions = Tensor::from_data(TensorData::new(act, [b, h, ad]), device);
    net.loss(cond, actions, noise, &t, ac)
}

/// Writes the policy checkpoint of epoch `done` (`out/epoch-NNNN/`, from the EMA weights
/// when the run keeps them) and returns its folder.
pub(crate) fn save_epoch(
    out: &Path,
    configs: &RunConfigs,
    provenance: &PolicyProvenance,
    training: &Training,
    (done, loss): (u64, f64),
) -> Result<PathBuf, PolicyLoadError> {
    let (pc, tc) = (&configs.policy, &configs.train);
    let ck = out.join(format!("epoch-{done:04}"));
    let mut prov = provenance.clone();
    prov.weights = Some(if tc.ema > 0.0 {
        Weights::Ema { ema_decay: tc.ema, ema_updates: training.state.ema_updates }
    } else {
        Weights::Raw(RawWeights::Raw)
    });
    let file = PolicyFile::diffusion(
        pc,
        &configs.normalisation,
        done,
        training.state.step,
        &prov,
        loss,
        configs.task.as_deref(),
    );
    let weights = if tc.ema > 0.0 { training.ema.module.clone() } else { training.net.valid() };
    write_policy(&ck, &file, &weights)?;
    Ok(ck)
}

/// The weights of the checkpoint a run starts from, which must have the run's
/// network config.
fn init_weights(src: &Path, pc: &DiffusionConfig, device: &Device) -> Result<DiffusionNet, PolicyLoadError> {
    let file = read_policy_file(src)?;
    let cfg = diffusion_config(src, &file)?;
    if cfg.net != pc.net || cfg.horizon != pc.horizon || cfg.train_steps != pc.train_steps {
        return Err(PolicyLoadError::new(
            src,
            format!(
                "its network ({:?}, horizon {}, {} diffusion steps) is not the run's ({:?}, horizon {}, {})",
                cfg.net, cfg.horizon, cfg.train_steps, pc.net, pc.horizon, pc.train_steps
            ),
        ));
    }
    diffusion_weights(src, pc, device)
}
