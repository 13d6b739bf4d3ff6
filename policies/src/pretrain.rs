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
use burn::nn::{Linear, LinearConfig};
use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use harness::driver::{Clock, Driver, read_state, write_state};
use harness::rng::Rng;
use harness::seed::derive;
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::data::{Demos, FrameLabels};
use crate::diffusion::frames_to_tensor;
use crate::dir::PolicyLoadError;
use crate::net::{NetConfig, ObsEncoder};
pub use crate::provenance::{ColumnError, PoseError};
use crate::symmetry::{augment_frame, augment_point, augment_pose};

/// Pose targets per frame: agent x, y, then block and goal x, y (world / 256 − 1),
/// cos θ, sin θ.
const POSE_DIM: usize = 10;
/// Frames per pre-training step.
const BATCH: usize = 64;
/// Linear warm-up steps of the pre-training learning rate.
const WARMUP: u64 = 100;

/// The encoder with a linear pose head.
#[derive(Module, Debug)]
pub struct PoseProbe {
    /// The frame encoder being trained.
    pub encoder: ObsEncoder,
    head: Linear,
}

impl PoseProbe {
    /// A fresh encoder and a head of `targets` outputs.
    pub fn new(cfg: &NetConfig, targets: usize, device: &Device) -> Self {
        Self {
            encoder: ObsEncoder::new(cfg, device),
            head: LinearConfig::new(cfg.feature_dim, targets).init(device),
        }
    }

    /// # Shapes
    /// `[n, 3, 96, 96]` → `[n, targets]`
    pub fn forward(&self, frames: Tensor<4>) -> Tensor<2> {
        self.head.forward(self.encoder.forward(frames))
    }
}

/// What the probe regresses: Push-T's poses, or standardised state columns.
enum Targets<'a> {
    PushT { block: &'a [[f32; 3]], goal: &'a [[f32; 3]] },
    Columns { names: &'a [String], values: &'a [f32], mean: Vec<f32>, std: Vec<f32> },
}

impl<'a> Targets<'a> {
    /// The targets of `demos`, columns standardised over the steps `train`; `None` when the
    /// demonstrations carry no labels.
    fn of(demos: &'a Demos, train: &[usize]) -> Option<Self> {
        match &demos.labels {
            FrameLabels::PushT { block, goal } => Some(Targets::PushT { block, goal }),
            FrameLabels::Columns { names, values } => {
                let k = names.len();
                let n = train.len().max(1) as f64;
                let mut mean = vec![0.0f64; k];
                for &i in train {
                    (0..k).for_each(|c| mean[c] += f64::from(values[i * k + c]) / n);
                }
                let mut var = vec![0.0f64; k];
                for &i in train {
                    (0..k).for_each(|c| var[c] += (f64::from(values[i * k + c]) - mean[c]).powi(2) / n);
                }
                // A constant column keeps unit scale instead of dividing by zero.
                let std = var.iter().map(|v| if v.sqrt() > 1e-9 { v.sqrt() as f32 } else { 1.0 }).collect();
                Some(Targets::Columns { names, values, mean: mean.iter().map(|&m| m as f32).collect(), std })
            }
            FrameLabels::None => None,
        }
    }

    /// Outputs per frame.
    fn dim(&self) -> usize {
        match self {
            Targets::PushT { .. } => POSE_DIM,
            Targets::Columns { names, .. } => names.len(),
        }
    }

    /// Symmetries frames may be mapped through (labels mapped alike).
    fn symmetries(&self) -> u64 {
        match self {
            Targets::PushT { .. } => 8,
            Targets::Columns { .. } => 1,
        }
    }

    /// The regression target of demonstration step `i` seen through symmetry `k`.
    fn at(&self, demos: &Demos, i: usize, k: u8) -> Vec<f32> {
        match self {
            Targets::PushT { block, goal } => {
                let p = demos.proprio_at(i);
                let a = augment_point([p[0], p[1]], k);
                let (b, g) = (augment_pose(block[i], k), augment_pose(goal[i], k));
                let w = |v: f32| v / 256.0 - 1.0;
                vec![
                    w(a[0]),
                    w(a[1]),
                    w(b[0]),
                    w(b[1]),
                    b[2].cos(),
                    b[2].sin(),
                    w(g[0]),
                    w(g[1]),
                    g[2].cos(),
                    g[2].sin(),
                ]
            }
            Targets::Columns { names, values, mean, std } => {
                let k = names.len();
                (0..k).map(|c| (values[i * k + c] - mean[c]) / std[c]).collect()
            }
        }
    }
}

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
    let mut probe = PoseProbe::new(cfg, targets.dim(), &device);
    let mut optim = AdamWConfig::new().with_weight_decay(1e-6).init();
    let mut state = PretrainState::default();
    if files[2].exists() || harness::checkpoint::pending(dir, harness::checkpoint::ENCODER) {
        harness::checkpoint::recover(dir, harness::checkpoint::ENCODER)
            .map_err(|e| err(&e.path, e.message))?;
    }
    if files[2].exists() {
        state = read_state(&files[2]).map_err(|e| err(&e.path, e.message))?;
        probe = probe.try_load_file(&files[0]).map_err(|e| err(&files[0], e.to_string()))?;
        optim = optim.load(&files[1]).map_err(|e| err(&files[1], e.to_string()))?;
    }
    // The log is shared with the U-Net stage's lines, which count "step" and are kept.
    // This stage's seconds start when it does, not with the session's clock.
    let mut driver = Driver::start(
        &dir.join("log.jsonl"),
        "encoder_step",
        state.step,
        state.elapsed_s,
        Clock::start(None),
    )
    .map_err(|e| err(&e.path, e.message))?;
    let save = |probe: &PoseProbe, optim: &burn::optim::ModuleOptimizer, state: &PretrainState| {
        save_encoder(dir, probe, optim, state)
    };
    let s = cfg.image_size;
    while state.step < p.steps {
        if clock.out_of_time() || driver.should_stop() {
            save(&probe, &optim, &state)?;
            return Ok((state, None));
        }
        let mut rng = Rng::new(derive(p.seed, &[u64::MAX - 1, state.step]));
        // Random frames, each through a random symmetry of the square for Push-T (8× more
        // distinct block and goal orientations than the demonstrations hold).
        let sym = targets.symmetries();
        let idx: Vec<(usize, u8)> = (0..BATCH)
            .map(|_| (train[rng.below(train.len() as u64) as usize], rng.below(sym) as u8))
            .collect();
        let owned: Vec<Vec<u8>> = idx.iter().map(|&(i, k)| augment_frame(demos.frame(i), s, k)).collect();
        let frames: Vec<&[u8]> = owned.iter().map(Vec::as_slice).collect();
        let y: Vec<f32> = idx.iter().flat_map(|&(i, k)| targets.at(demos, i, k)).collect();
        let y = Tensor::from_data(TensorData::new(y, [BATCH, targets.dim()]), &device);
        let loss = (probe.forward(frames_to_tensor(&frames, s, &device)) - y).powf_scalar(2.0).mean();
        let lv: f64 = loss.clone().into_scalar::<f32>().into();
        if !lv.is_finite() {
            return Err(err(
                dir,
                format!("non-finite pose loss at encoder pre-training step {}", state.step),
            ));
        }
        let grads = GradientsParams::from_grads(loss.backward(), &probe);
        let lr = p.lr * ((state.step + 1) as f64 / WARMUP as f64).min(1.0);
        probe = optim.step(lr, probe, grads);
        state.step += 1;
        state.elapsed_s = driver.elapsed_s();
        on_step(state.step, lv);
        if state.step.is_multiple_of(50) || state.step == p.steps {
            // No held-out episode (fewer than 20 demonstrations): no held-out error.
            if (state.step.is_multiple_of(500) || state.step == p.steps) && !test.is_empty() {
                let valid = probe.valid();
                match &targets {
                    Targets::PushT { .. } => {
                        state.heldout = Some(pose_error(&valid, &targets, demos, &test, s))
                    }
                    Targets::Columns { .. } => {
                        state.heldout_columns = Some(column_error(&valid, &targets, demos, &test, s));
                    }
                }
            }
            let line = json!({"encoder_step": state.step, "loss": lv, "heldout": state.heldout,
                "heldout_columns": state.heldout_columns, "elapsed_s": state.elapsed_s});
            driver.log(&line).map_err(|e| err(&e.path, e.message))?;
            save(&probe, &optim, &state)?;
        }
    }
    save(&probe, &optim, &state)?;
    Ok((state, Some(probe)))
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
    let fail = |e: harness::runfile::RunFileError| err(&e.path, e.message);
    let mut stage = harness::checkpoint::begin(dir, harness::checkpoint::ENCODER).map_err(fail)?;
    let p = ["encoder.bpk", "encoder_optimizer.bpk", "encoder_state.json"].map(|n| stage.path(n));
    probe.clone().save_file(&p[0]).map_err(|e| err(&p[0], e.to_string()))?;
    optim.save(&p[1]).map_err(|e| err(&p[1], e.to_string()))?;
    write_state(&p[2], state).map_err(fail)?;
    stage.commit().map_err(fail)
}

/// Up to 512 evenly spaced steps of `steps`, and the probe's outputs on their frames
/// (`dim` per step).
fn predict(probe: &PoseProbe, demos: &Demos, steps: &[usize], s: usize) -> (Vec<usize>, Vec<f32>) {
    let pick: Vec<usize> = if steps.len() <= 512 {
        steps.to_vec()
    } else {
        (0..512).map(|k| steps[k * steps.len() / 512]).collect()
    };
    let device = probe.head.weight.device();
    let mut v = Vec::new();
    for part in pick.chunks(128) {
        let frames: Vec<&[u8]> = part.iter().map(|&i| demos.frame(i)).collect();
        let out = probe.forward(frames_to_tensor(&frames, s, &device));
        v.extend(out.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default());
    }
    (pick, v)
}

/// Mean Push-T pose errors of `probe` on (up to 512 evenly spaced) frames of `steps`.
fn pose_error(probe: &PoseProbe, targets: &Targets, demos: &Demos, steps: &[usize], s: usize) -> PoseError {
    let (pick, v) = predict(probe, demos, steps, s);
    let mut e = PoseError::default();
    if pick.is_empty() {
        return e;
    }
    for (k, &i) in pick.iter().enumerate() {
        let (q, t) = (&v[k * POSE_DIM..(k + 1) * POSE_DIM], targets.at(demos, i, 0));
        let dist = |a: usize| 256.0 * f64::from(q[a] - t[a]).hypot(f64::from(q[a + 1] - t[a + 1]));
        let angle = |a: usize| {
            let d = f64::from(q[a + 1]).atan2(f64::from(q[a])) - f64::from(t[a + 1]).atan2(f64::from(t[a]));
            d.sin().atan2(d.cos()).abs().to_degrees()
        };
        e.agent += dist(0);
        e.block += dist(2);
        e.angle_deg += angle(4);
        e.goal += dist(6);
        e.goal_angle_deg += angle(8);
    }
    let n = pick.len() as f64;
    PoseError {
        agent: e.agent / n,
        block: e.block / n,
        angle_deg: e.angle_deg / n,
        goal: e.goal / n,
        goal_angle_deg: e.goal_angle_deg / n,
    }
}

/// Mean absolute error of each named column on (up to 512 evenly spaced) frames of
/// `steps`, in the state's units (standardised outputs scaled back by the column's std).
fn column_error(
    probe: &PoseProbe,
    targets: &Targets,
    demos: &Demos,
    steps: &[usize],
    s: usize,
) -> Vec<ColumnError> {
    let Targets::Columns { names, std, .. } = targets else { return Vec::new() };
    let (pick, v) = predict(probe, demos, steps, s);
    let k = names.len();
    let mut sum = vec![0.0f64; k];
    for (j, &i) in pick.iter().enumerate() {
        let t = targets.at(demos, i, 0);
        (0..k).for_each(|c| sum[c] += f64::from((v[j * k + c] - t[c]).abs() * std[c]));
    }
    let n = pick.len().max(1) as f64;
    names.iter().zip(sum).map(|(name, e)| ColumnError { name: name.clone(), mean_abs_error: e / n }).collect()
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
