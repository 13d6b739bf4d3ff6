//! Training a diffusion policy, saving a policy checkpoint every few epochs.
//!
//! The checkpoints along one run form a graded policy set: early epochs act
//! poorly, later ones well — what `rank` needs to measure agreement on.
//!
//! Output folder:
//! - `epoch-NNNN/`: a loadable policy checkpoint (`policy.json` + `model.bpk`);
//! - `.train/`: the resumable training state (`config.json`, `model.bpk`,
//!   `ema.bpk`, `optimizer.bpk`, `state.json`, `log.jsonl`); hidden so that policy
//!   loaders skip it.
//!
//! An epoch is one pass over every sample in a permutation that is a function of
//! (seed, epoch), so a resumed run visits exactly the samples an uninterrupted one would.

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use harness::driver::{Clock, Driver};
use harness::rng::Rng;
use harness::seed::derive;
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::data::Demos;
use crate::diffusion::{DiffusionConfig, DiffusionNet, Normalisation, alphas_cumprod, frames_to_tensor};
use crate::dir::{
    PolicyFile, PolicyLoadError, diffusion_config, diffusion_weights, read_policy_file, write_policy,
};
use crate::pretrain::{Pretrain, encode_frames, pretrain_encoder};
use crate::provenance::{EncoderPretraining, PolicyProvenance, RawWeights, Weights};
use nn::optim::Ema;

/// Training hyper-parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolicyTrainConfig {
    /// Epochs in total.
    pub epochs: u64,
    /// Save a policy checkpoint every this many epochs (and after the last).
    pub save_every: u64,
    /// Samples per step.
    pub batch: usize,
    /// Learning rate after warm-up (AdamW β = (0.95, 0.999)); constant, so a run can be
    /// extended with more epochs without changing what was already trained.
    pub lr: f64,
    /// Linear warm-up steps.
    pub warmup: u64,
    /// AdamW weight decay.
    pub weight_decay: f64,
    /// Seed of the weights, sample order and noise.
    pub seed: u64,
    /// Save the training state every this many steps.
    pub checkpoint_every: u64,
    /// Pose pre-training steps of the frame encoder ([`crate::pretrain`]). 0 trains
    /// encoder and U-Net end to end (Chi et al.); more pre-trains the encoder, freezes
    /// it and trains the U-Net alone on cached features.
    #[serde(default)]
    pub encoder_steps: u64,
    /// Peak learning rate of the pose pre-training.
    #[serde(default = "default_encoder_lr")]
    pub encoder_lr: f64,
    /// Decay of the exponential moving average of the weights that checkpoints are
    /// saved from (Chi et al. sample from EMA weights); 0 saves the raw weights. The
    /// effective decay warms up as `min(ema, (1 + k) / (10 + k))` after k updates.
    #[serde(default)]
    pub ema: f64,
    /// A diffusion-policy checkpoint folder the run starts from instead of fresh
    /// weights (fine-tuning, e.g. on more demonstrations). Its encoder stays frozen
    /// (the U-Net trains on cached features) and the run must use its network config.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init_from: Option<PathBuf>,
}

fn default_encoder_lr() -> f64 {
    1e-3
}

/// How to run a session.
#[derive(Clone, Copy, Debug, Default)]
pub struct PolicyRun {
    /// Continue from `.train/`.
    pub resume: bool,
    /// When resuming, train to this many epochs in total instead of the saved number.
    pub epochs: Option<u64>,
    /// Stop (with a saved state) after this many minutes.
    pub max_minutes: Option<f64>,
    /// When resuming, use this EMA decay from now on (an EMA started mid-run begins
    /// at the current weights).
    pub ema: Option<f64>,
}

/// What a training run is doing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Pose pre-training of the frame encoder.
    Encoder,
    /// Training the policy (the U-Net, and the encoder when end to end).
    Policy,
}

/// A progress report.
#[derive(Clone, Debug)]
pub struct PolicyProgress {
    /// The phase `step` and `total` count.
    pub phase: Phase,
    /// Steps done / in total.
    pub step: u64,
    /// Steps in total.
    pub total: u64,
    /// Current epoch (1-based while running).
    pub epoch: u64,
    /// Last batch loss.
    pub loss: f64,
}

/// The resumable state.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
struct State {
    step: u64,
    elapsed_s: f64,
    /// EMA updates so far (they start when `ema` is first set, possibly mid-run).
    #[serde(default)]
    ema_updates: u64,
}

/// Saved configs of a run.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunConfigs {
    /// The policy.
    pub policy: DiffusionConfig,
    /// Training.
    pub train: PolicyTrainConfig,
    /// Data normalisation.
    pub normalisation: Normalisation,
    /// How the run was made (data, command), copied into every checkpoint.
    pub provenance: PolicyProvenance,
    /// The task of the demonstrations, recorded in every checkpoint's `policy.json`.
    #[serde(default)]
    pub task: Option<String>,
}

/// What a session ended with.
#[derive(Clone, Debug)]
pub struct PolicyOutcome {
    /// Steps done.
    pub step: u64,
    /// Steps in total.
    pub total: u64,
    /// Checkpoints written in this session.
    pub saved: Vec<PathBuf>,
    /// Mean loss of the last 50 steps.
    pub loss: f64,
    /// Training seconds over all sessions, as the state file records them.
    pub elapsed_s: f64,
}

/// Trains (or resumes) a diffusion policy into `out` on `inner` (its autodiff
/// wrapper for the gradients; see `nn::device`).
///
/// # Errors
/// [`PolicyLoadError`] naming the file for unreadable state or I/O failures, or a
/// non-finite loss (naming the step).
pub fn train_policy(
    demos: &Demos,
    out: &Path,
    configs: &RunConfigs,
    run: PolicyRun,
    inner: &Device,
    on_progress: &mut dyn FnMut(&PolicyProgress),
) -> Result<PolicyOutcome, PolicyLoadError> {
    let dir = out.join(".train");
    let cfg_path = dir.join("config.json");
    // This session's command, recorded when resuming (the saved provenance holds the first).
    let session_command = configs.provenance.command.clone();
    let configs =
        harness::runfile::resume_or_start(&cfg_path, configs.clone(), run.resume, |c: &mut RunConfigs| {
            let extend = run.epochs.filter(|&e| e != c.train.epochs);
            c.train.epochs = extend.unwrap_or(c.train.epochs);
            let ema = run.ema.filter(|&d| d != c.train.ema);
            c.train.ema = ema.unwrap_or(c.train.ema);
            extend.is_some() || ema.is_some()
        })
        .map_err(|e| PolicyLoadError::new(&e.path, e.message))?;
    let (pc, tc) = (&configs.policy, &configs.train);
    let device = inner.clone().autodiff();
    let (o, h, s) = (pc.net.obs_horizon, pc.horizon, pc.net.image_size);
    let (pd, ad) = (demos.proprio_dim, demos.action_dim);
    if (pc.net.proprio(), pc.net.action_dim) != (pd, ad) {
        return Err(PolicyLoadError::new(
            out,
            format!(
                "the policy takes {}-entry proprioception and {}-entry actions, the demonstrations have {pd} and {ad}",
                pc.net.proprio(),
                pc.net.action_dim
            ),
        ));
    }
    let n = demos.len();
    let per_epoch = n.div_ceil(tc.batch.max(1)) as u64;
    let total = per_epoch * tc.epochs;
    let mut net = DiffusionNet::new(pc, &device);
    let mut optim = AdamWConfig::new()
        .with_beta_1(0.95)
        .with_beta_2(0.999)
        .with_weight_decay(tc.weight_decay as f32)
        .init();
    let paths = ["model.bpk", "optimizer.bpk", "state.json", "ema.bpk"].map(|p| dir.join(p));
    let mut state = State::default();
    if run.resume {
        harness::checkpoint::recover(&dir, harness::checkpoint::MAIN)
            .map_err(|e| PolicyLoadError::new(&e.path, e.message))?;
        net = net.try_load_file(&paths[0]).map_err(|e| PolicyLoadError::new(&paths[0], e.to_string()))?;
        optim = optim.load(&paths[1]).map_err(|e| PolicyLoadError::new(&paths[1], e.to_string()))?;
        state =
            harness::driver::read_state(&paths[2]).map_err(|e| PolicyLoadError::new(&e.path, e.message))?;
    }
    if let Some(src) = tc.init_from.as_ref().filter(|_| !run.resume) {
        net = init_weights(src, pc, &device)?;
    }
    let mut ema = Ema::new(&net, tc.ema);
    if tc.ema > 0.0 && state.ema_updates > 0 {
        let module = ema.module.clone();
        ema.module =
            module.try_load_file(&paths[3]).map_err(|e| PolicyLoadError::new(&paths[3], e.to_string()))?;
    }
    let save_state =
        |net: &DiffusionNet, ema: &Ema<DiffusionNet>, optim: &burn::optim::ModuleOptimizer, state: &State| {
            // The files are one checkpoint: staged, then committed by a manifest.
            let fail = |e: harness::runfile::RunFileError| PolicyLoadError::new(&e.path, e.message);
            let mut stage = harness::checkpoint::begin(&dir, harness::checkpoint::MAIN).map_err(fail)?;
            let p = ["model.bpk", "optimizer.bpk", "state.json"].map(|n| stage.path(n));
            net.clone().save_file(&p[0]).map_err(|e| PolicyLoadError::new(&p[0], e.to_string()))?;
            optim.save(&p[1]).map_err(|e| PolicyLoadError::new(&p[1], e.to_string()))?;
            // The manifest lists only what this checkpoint has (no EMA before its first update).
            if state.ema_updates > 0 {
                let e = stage.path("ema.bpk");
                ema.module.clone().save_file(&e).map_err(|err| PolicyLoadError::new(&e, err.to_string()))?;
            }
            harness::driver::write_state(&p[2], state).map_err(fail)?;
            stage.commit().map_err(fail)
        };
    // One clock for both stages: `--max-minutes` bounds the session, pre-training included.
    let clock = Clock::start(run.max_minutes);
    let mut provenance = configs.provenance.clone();
    if run.resume {
        provenance.resumed_with = Some(session_command);
    }
    let features = if tc.encoder_steps > 0 {
        let p = Pretrain { steps: tc.encoder_steps, lr: tc.encoder_lr, seed: tc.seed };
        let enc_total = tc.encoder_steps;
        let (ps, probe) = pretrain_encoder(demos, &pc.net, p, &dir, clock, inner, &mut |step, loss| {
            on_progress(&PolicyProgress { phase: Phase::Encoder, step, total: enc_total, epoch: 0, loss });
        })?;
        let Some(probe) = probe else {
            // Stopped during pre-training: the run's own state is what `--resume` looks for.
            save_state(&net, &ema, &optim, &state)?;
            return Ok(PolicyOutcome {
                step: state.step,
                total,
                saved: Vec::new(),
                loss: f64::NAN,
                elapsed_s: state.elapsed_s,
            });
        };
        provenance.encoder_pretraining = Some(EncoderPretraining {
            heldout_mean_abs_error: ps.heldout_columns.clone(),
            heldout_pose_error: ps.heldout,
            steps: ps.step,
        });
        if state.step == 0 {
            net.encoder = probe.encoder;
            ema = Ema::new(&net, tc.ema);
        }
        tracing::info!(frames = demos.len(), "encoding every frame with the frozen encoder");
        Some(encode_frames(&net.encoder.valid(), demos, s, inner))
    } else if tc.init_from.is_some() {
        // The starting checkpoint's encoder (saved unchanged in `.train/model.bpk` on resume).
        tracing::info!(frames = demos.len(), "encoding every frame with the starting checkpoint's encoder");
        Some(encode_frames(&net.encoder.valid(), demos, s, inner))
    } else {
        None
    };
    let ac = alphas_cumprod(pc.train_steps);
    let mut driver = Driver::start(&dir.join("log.jsonl"), "step", state.step, state.elapsed_s, clock)
        .map_err(|e| PolicyLoadError::new(&e.path, e.message))?;
    let mut recent = Vec::new();
    let mut saved = Vec::new();
    let mut order: (u64, Vec<usize>) = (u64::MAX, Vec::new());
    while state.step < total {
        if driver.should_stop() {
            break;
        }
        let epoch = state.step / per_epoch;
        if order.0 != epoch {
            order = (epoch, permutation(n, derive(tc.seed, &[epoch])));
        }
        let k = (state.step % per_epoch) as usize * tc.batch;
        let batch = &order.1[k..(k + tc.batch).min(n)];
        let b = batch.len();
        // Observation steps of the batch, `o` per sample (oldest first).
        let mut obs = Vec::with_capacity(b * o);
        let (mut pos, mut act) = (Vec::with_capacity(b * o * pd), Vec::with_capacity(b * h * ad));
        for &t in batch {
            let (oi, ai) = demos.sample_indices(t, o, h);
            obs.extend_from_slice(&oi);
            pos.extend(
                oi.iter().flat_map(|&i| configs.normalisation.agent_pos.normalise(demos.proprio_at(i))),
            );
            act.extend(ai.iter().flat_map(|&i| configs.normalisation.action.normalise(demos.action_at(i))));
        }
        let mut rng = Rng::new(derive(tc.seed, &[u64::MAX, state.step]));
        let t: Vec<usize> = (0..b).map(|_| rng.below(pc.train_steps as u64) as usize).collect();
        let noise = Tensor::from_data(TensorData::new(rng.normals_f32(b * h * ad), [b, h, ad]), &device);
        let cond = match &features {
            // Frozen encoder: [b, o·(f + pd)] from the cache, no gradient reaches the encoder.
            Some(cache) => {
                let f = pc.net.feature_dim;
                let mut c = Vec::with_capacity(b * o * (f + pd));
                for (j, &i) in obs.iter().enumerate() {
                    c.extend_from_slice(&cache[i * f..(i + 1) * f]);
                    c.extend_from_slice(&pos[j * pd..(j + 1) * pd]);
                }
                Tensor::from_data(TensorData::new(c, [b, o * (f + pd)]), &device)
            }
            None => {
                let frames: Vec<&[u8]> = obs.iter().map(|&i| demos.frame(i)).collect();
                net.obs_cond(
                    frames_to_tensor(&frames, s, &device),
                    Tensor::from_data(TensorData::new(pos, [b, o, pd]), &device),
                )
            }
        };
        let actions = Tensor::from_data(TensorData::new(act, [b, h, ad]), &device);
        let loss = net.loss(cond, actions, noise, &t, &ac);
        let lv: f64 = loss.clone().into_scalar::<f32>().into();
        if !lv.is_finite() {
            return Err(PolicyLoadError::new(
                out,
                format!("non-finite loss at training step {}", state.step),
            ));
        }
        let grads = GradientsParams::from_grads(loss.backward(), &net);
        net = optim.step(lr_at(state.step, tc), net, grads);
        state.step += 1;
        if tc.ema > 0.0 {
            let k = state.ema_updates as f64;
            ema.decay = tc.ema.min((1.0 + k) / (10.0 + k));
            ema.update(&net);
            state.ema_updates += 1;
        }
        state.elapsed_s = driver.elapsed_s();
        recent.push(lv);
        if recent.len() > 50 {
            recent.remove(0);
        }
        let line = json!({"step": state.step, "epoch": epoch + 1, "loss": lv, "elapsed_s": state.elapsed_s});
        driver.log(&line).map_err(|e| PolicyLoadError::new(&e.path, e.message))?;
        if state.step.is_multiple_of(per_epoch) {
            let done = state.step / per_epoch;
            if done.is_multiple_of(tc.save_every) || done == tc.epochs {
                let ck = out.join(format!("epoch-{done:04}"));
                let mut prov = provenance.clone();
                prov.weights = Some(if tc.ema > 0.0 {
                    Weights::Ema { ema_decay: tc.ema, ema_updates: state.ema_updates }
                } else {
                    Weights::Raw(RawWeights::Raw)
                });
                let file = PolicyFile::diffusion(
                    pc,
                    &configs.normalisation,
                    done,
                    state.step,
                    &prov,
                    lv,
                    configs.task.as_deref(),
                );
                let weights = if tc.ema > 0.0 { ema.module.clone() } else { net.valid() };
                write_policy(&ck, &file, &weights)?;
                saved.push(ck);
            }
        }
        if state.step.is_multiple_of(tc.checkpoint_every) || state.step.is_multiple_of(per_epoch) {
            save_state(&net, &ema, &optim, &state)?;
        }
        on_progress(&PolicyProgress {
            phase: Phase::Policy,
            step: state.step,
            total,
            epoch: epoch + 1,
            loss: lv,
        });
    }
    save_state(&net, &ema, &optim, &state)?;
    let loss = recent.iter().sum::<f64>() / recent.len().max(1) as f64;
    Ok(PolicyOutcome { step: state.step, total, saved, loss, elapsed_s: state.elapsed_s })
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

/// Linear warm-up, then constant.
fn lr_at(step: u64, tc: &PolicyTrainConfig) -> f64 {
    if step < tc.warmup { tc.lr * (step + 1) as f64 / tc.warmup as f64 } else { tc.lr }
}

/// A Fisher–Yates permutation of 0..n from a seed.
fn permutation(n: usize, seed: u64) -> Vec<usize> {
    let mut rng = Rng::new(seed);
    let mut p: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        p.swap(i, rng.below(i as u64 + 1) as usize);
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn permutation_is_a_permutation_and_seeded() {
        let mut p = permutation(50, 3);
        assert_eq!(p, permutation(50, 3));
        assert_ne!(p, permutation(50, 4));
        p.sort_unstable();
        assert_eq!(p, (0..50).collect::<Vec<_>>());
    }
}
