//! Pose pre-training of the frame encoder, and the frozen-encoder feature cache.
//!
//! On this 2-core CPU an end-to-end diffusion-policy step spends nearly all its
//! time in the frame encoder, and the ~20k end-to-end steps a Push-T policy needs
//! would take most of a day. So the trainer can instead
//! 1. train the encoder for a few thousand steps to regress from one frame what it
//!    shows (the dataset's privileged state is the label): Push-T's agent, block
//!    and (randomised) goal poses; for other tasks the state columns the task names
//!    ([`harness::task::Task::frame_labels`]: robomimic's object, end effector and
//!    fingers), each standardised over the training frames,
//! 2. freeze it and encode every demonstration frame once ([`encode_frames`]),
//! 3. train only the 1-D U-Net on the cached features — a far cheaper step.
//!
//! The saved checkpoint is an ordinary `diffusion` policy (encoder + U-Net), so
//! inference does not change: the policy still sees only pixels and its own
//! agent position. Every 20th episode is held out of the pose regression and
//! reported as its pose error (per column, in the state's units, for named
//! columns). Push-T frames are augmented with the 8 symmetries of the square world
//! (labels mapped with them): without that, the encoder memorises the few hundred
//! goal orientations of the demonstrations and does not generalise orientation to
//! new episodes (held-out angle error stayed ~70°). Other tasks' scenes have no
//! such symmetry and are not augmented.
//!
//! Files in the run's `.train/`: `encoder.bpk`, `encoder_optimizer.bpk`,
//! `encoder_state.json`, and one `encoder` line per 50 steps in `log.jsonl`.

use std::path::Path;

use burn::module::Module;

use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use harness::driver::{Clock, Driver, read_state, write_state};
use harness::rng::Rng;
use harness::seed::derive;
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::data::Demos;
use crate::diffusion::frames_to_tensor;
use crate::dir::PolicyLoadError;
use crate::net::{NetConfig, ObsEncoder};
use crate::pose_probe::{PoseProbe, Targets, column_error, pose_error};
pub use crate::provenance::{ColumnError, PoseError};
use crate::symmetry::augment_frame;

/// Frames per pre-training step.
const BATCH: usize = 64;
/// Linear warm-up steps of the pre-training learning rate.
const WARMUP: u64 = 100;

/// Pre-training progress, saved as `encoder_state.json`.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct PretrainState {
    /// Steps done.
    pub step: u64,
    /// Training seconds over all sessions.
    pub elapsed_s: f64,
    /// Held-out error at the last evaluation (Push-T).
    pub heldout: Option<PoseError>,
    /// Held-out mean absolute error of each named column, in the state's units
    /// (tasks other than Push-T).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heldout_columns: Option<Vec<ColumnError>>,
}

/// What pre-training is asked to do.
#[derive(Clone, Copy, Debug)]
pub struct Pretrain {
    /// Steps in total.
    pub steps: u64,
    /// Peak learning rate (AdamW).
    pub lr: f64,
    /// Seed of the weights and frame order.
    pub seed: u64,
}

fn held_out(episode: usize) -> bool {
    episode % 20 == 19
}

/// Trains (or continues) the pose probe in `dir` until `p.steps`, the deadline of
/// `clock` (the policy run's session) or Ctrl-C.
/// Returns the state and the probe (training device) when it has finished, the
/// state alone when it stopped early.
///
/// # Errors
/// [`PolicyLoadError`] naming the file for unreadable or unwritable state, or a
/// non-finite loss (naming the step).
pub fn pretrain_encoder(
    demos: &Demos,
    cfg: &NetConfig,
    p: Pretrain,
    dir: &Path,
    clock: Clock,
    inner: &Device,
    on_step: &mut dyn FnMut(u64, f64),
) -> Result<(PretrainState, Option<PoseProbe>), PolicyLoadError> {
    let files = ["encoder.bpk", "encoder_optimizer.bpk", "encoder_state.json"].map(|f| dir.join(f));
    let err = |path: &Path, e: String| PolicyLoadError::new(path, e);
    let device = inner.clone().autodiff();
    let (train, test) = split_steps(demos);
    if train.is_empty() {
        return Err(err(dir, "encoder pre-training: no training episodes (every 20th is held out)".into()));
    }
    let targets = Targets::of(demos, &train).ok_or_else(|| {
        err(dir, "encoder pre-training: the dataset's task names no frame labels to pre-train on".into())
    })?;
    // The probe's fresh weights are a function of the seed, as the policy's are.
    device.seed(derive(p.seed, &[u64::MAX - 3]));
    let mut probe = PoseProbe::new(cfg, targets.dim(), &device);
    let mut optim = AdamWConfig::new().with_weight_decay(1e-6).init();
    let mut state = PretrainState::default();
    if files[2].exists() || harness::checkpoint::pending(dir, harness::checkpoint::ENCODER) {
        harness::checkpoint::recover(dir, harness::checkpoint::ENCODER)?;
    }
    if files[2].exists() {
        state = read_state(&files[2])?;
        probe = probe.try_load_file(&files[0]).map_err(|e| err(&files[0], e.to_string()))?;
        optim = optim.load(&files[1]).map_err(|e| err(&files[1], e.to_string()))?;
    }
    // The log is shared with the U-Net stage's lines, which count "step" and are kept.
    // This stage's seconds start when it does, not with the session's clock, which it stops at.
    let mut driver = Driver::start(
        &dir.join("log.jsonl"),
        "encoder_step",
        state.step,
        state.elapsed_s,
        Clock::start(None),
    )?
    .stopping_at(clock.deadline());
    let mut steps = PretrainSteps {
        demos,
        targets: &targets,
        sets: (&train, &test),
        p,
        s: cfg.image_size,
        dir,
        device: &device,
        state,
        loss: f64::NAN,
        on_step,
    };
    let ((probe, _), finished) = driver.train(&mut steps, (probe, optim))?;
    Ok((steps.state, finished.then_some(probe)))
}

/// The pose probe's steps for the shared loop ([`Driver::train`]): 64 training frames, each
/// through a random symmetry where the task has them, the mean squared error of the probe's
/// outputs; every 50 steps a log line and a checkpoint, every 500 the held-out error.
struct PretrainSteps<'a> {
    demos: &'a Demos,
    targets: &'a Targets<'a>,
    /// The training steps and the held-out ones.
    sets: (&'a [usize], &'a [usize]),
    p: Pretrain,
    /// The frames' side.
    s: usize,
    dir: &'a Path,
    device: &'a Device,
    state: PretrainState,
    loss: f64,
    on_step: &'a mut dyn FnMut(u64, f64),
}

impl harness::driver::Steps for PretrainSteps<'_> {
    type Net = (PoseProbe, burn::optim::ModuleOptimizer);
    type Line = serde_json::Value;
    type Error = PolicyLoadError;

    fn done(&self) -> u64 {
        self.state.step
    }

    fn total(&self) -> u64 {
        self.p.steps
    }

    fn step(
        &mut self,
        (probe, mut optim): Self::Net,
        elapsed_s: &dyn Fn() -> f64,
    ) -> harness::driver::Stepped<Self> {
        let (p, s, demos, targets) = (self.p, self.s, self.demos, self.targets);
        let (train, test) = self.sets;
        let mut rng = Rng::new(derive(p.seed, &[u64::MAX - 1, self.state.step]));
        // Random frames, each through a random symmetry of the square for Push-T (8× more
        // distinct block and goal orientations than the demonstrations hold).
        let sym = targets.symmetries();
        let idx: Vec<(usize, u8)> = (0..BATCH)
            .map(|_| (train[rng.below(train.len() as u64) as usize], rng.below(sym) as u8))
            .collect();
        let owned: Vec<Vec<u8>> = idx.iter().map(|&(i, k)| augment_frame(demos.frame(i), s, k)).collect();
        let frames: Vec<&[u8]> = owned.iter().map(Vec::as_slice).collect();
        let y: Vec<f32> = idx.iter().flat_map(|&(i, k)| targets.at(demos, i, k)).collect();
        let y = Tensor::from_data(TensorData::new(y, [BATCH, targets.dim()]), self.device);
        let loss = (probe.forward(frames_to_tensor(&frames, s, self.device)) - y).powf_scalar(2.0).mean();
        let lv: f64 = loss.clone().into_scalar::<f32>().into();
        if !lv.is_finite() {
            let what = format!("non-finite pose loss at encoder pre-training step {}", self.state.step);
            return Err(PolicyLoadError::new(self.dir, what));
        }
        let grads = GradientsParams::from_grads(loss.backward(), &probe);
        let lr = p.lr * ((self.state.step + 1) as f64 / WARMUP as f64).min(1.0);
        let probe = optim.step(lr, probe, grads);
        let state = &mut self.state;
        state.step += 1;
        state.elapsed_s = elapsed_s();
        self.loss = lv;
        if !self.checkpoint_due() {
            return Ok(((probe, optim), None));
        }
        let state = &mut self.state;
        // No held-out episode (fewer than 20 demonstrations): no held-out error.
        if (state.step.is_multiple_of(500) || state.step == p.steps) && !test.is_empty() {
            let valid = probe.valid();
            match targets {
                Targets::PushT { .. } => state.heldout = Some(pose_error(&valid, targets, demos, test, s)),
                Targets::Columns { .. } => {
                    state.heldout_columns = Some(column_error(&valid, targets, demos, test, s));
                }
            }
        }
        let line = json!({"encoder_step": state.step, "loss": lv, "heldout": state.heldout,
            "heldout_columns": state.heldout_columns, "elapsed_s": state.elapsed_s});
        Ok(((probe, optim), Some(line)))
    }

    fn checkpoint_due(&self) -> bool {
        self.state.step.is_multiple_of(50) || self.state.step == self.p.steps
    }

    fn save(&mut self, (probe, optim): &Self::Net, _elapsed_s: f64) -> Result<(), PolicyLoadError> {
        save_encoder(self.dir, probe, optim, &self.state)
    }

    fn progress(&mut self) {
        (self.on_step)(self.state.step, self.loss);
    }
}

/// The demonstrations' steps in training episodes and in held-out ones (every 20th).
fn split_steps(demos: &Demos) -> (Vec<usize>, Vec<usize>) {
    let mut sets = (Vec::new(), Vec::new());
    for (e, r) in demos.episodes.iter().enumerate() {
        if held_out(e) { sets.1.extend(r.clone()) } else { sets.0.extend(r.clone()) }
    }
    sets
}

/// Writes the probe, its optimiser and `state` as the encoder stage's checkpoint in `dir`:
/// the three files staged, then committed by a manifest.
///
/// # Errors
/// A file that cannot be written, naming it.
fn save_encoder(
    dir: &Path,
    probe: &PoseProbe,
    optim: &burn::optim::ModuleOptimizer,
    state: &PretrainState,
) -> Result<(), PolicyLoadError> {
    let err = |path: &Path, e: String| PolicyLoadError::new(path, e);
    let mut stage = harness::checkpoint::begin(dir, harness::checkpoint::ENCODER)?;
    let p = ["encoder.bpk", "encoder_optimizer.bpk", "encoder_state.json"].map(|n| stage.path(n));
    probe.clone().save_file(&p[0]).map_err(|e| err(&p[0], e.to_string()))?;
    optim.save(&p[1]).map_err(|e| err(&p[1], e.to_string()))?;
    write_state(&p[2], state)?;
    Ok(stage.commit()?)
}

/// Features of every demonstration frame (`[n · feature_dim]`, frame-major) from a
/// frozen encoder.
pub fn encode_frames(encoder: &ObsEncoder, demos: &Demos, s: usize, device: &Device) -> Vec<f32> {
    let n = demos.len();
    let mut out = Vec::new();
    for start in (0..n).step_by(256) {
        let frames: Vec<&[u8]> = (start..(start + 256).min(n)).map(|i| demos.frame(i)).collect();
        let f = encoder.forward(frames_to_tensor(&frames, s, device));
        out.extend(f.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::FrameLabels;

    #[test]
    fn targets_are_normalised_poses() {
        let d = Demos {
            frames: vec![],
            proprio: vec![256.0, 384.0],
            proprio_dim: 2,
            actions: vec![0.0; 2],
            action_dim: 2,
            labels: FrameLabels::PushT {
                block: vec![[128.0, 512.0, std::f32::consts::FRAC_PI_2]],
                goal: vec![[0.0, 256.0, std::f32::consts::PI]],
            },
            size: 1,
            episodes: std::iter::once(0..1).collect(),
        };
        // 256/256 − 1 = 0, 384/256 − 1 = 0.5, 128/256 − 1 = −0.5, 512/256 − 1 = 1; θ = π/2;
        // goal 0/256 − 1 = −1, 256/256 − 1 = 0, θ = π (cos −1, sin 0).
        let targets = Targets::of(&d, &[0]).unwrap();
        let t = targets.at(&d, 0, 0);
        let want = [0.0, 0.5, -0.5, 1.0, 0.0, 1.0, -1.0, 0.0, -1.0, 0.0];
        assert!(t.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-6), "{t:?}");
        assert_eq!((targets.dim(), targets.symmetries()), (10, 8));
    }

    #[test]
    fn named_columns_are_standardised_over_the_training_steps() {
        let d = Demos {
            frames: vec![],
            proprio: vec![0.0; 3],
            proprio_dim: 1,
            actions: vec![0.0; 3],
            action_dim: 1,
            // Column a: 1, 3, 100; column b: 5, 5, 5 (constant).
            labels: FrameLabels::Columns {
                names: vec!["a".into(), "b".into()],
                values: vec![1.0, 5.0, 3.0, 5.0, 100.0, 5.0],
            },
            size: 1,
            episodes: std::iter::once(0..3).collect(),
        };
        // Over training steps 0 and 1: a has mean 2, std 1 (population: ((1−2)² + (3−2)²)/2 = 1);
        // b is constant: mean 5, unit scale. Step 2 (held out) maps a = 100 to (100 − 2)/1 = 98.
        let targets = Targets::of(&d, &[0, 1]).unwrap();
        assert_eq!((targets.dim(), targets.symmetries()), (2, 1));
        assert_eq!(targets.at(&d, 0, 0), vec![-1.0, 0.0]);
        assert_eq!(targets.at(&d, 2, 0), vec![98.0, 0.0]);
        let none = Demos { labels: FrameLabels::None, ..d };
        assert!(Targets::of(&none, &[0]).is_none());
    }

    #[test]
    fn every_twentieth_episode_is_held_out() {
        let held: Vec<usize> = (0..60).filter(|&e| held_out(e)).collect();
        assert_eq!(held, vec![19, 39, 59]);
    }
}
