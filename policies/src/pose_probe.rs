//! The pose probe a policy's frame encoder is pre-trained as ([`crate::pretrain`]): the
//! encoder with a linear head, the targets it learns per frame (Push-T's agent, block and goal
//! poses, under the square's symmetries; another task's named state columns), and its held-out
//! errors.

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::{Device, Tensor};

use crate::data::{Demos, FrameLabels};
use crate::diffusion::frames_to_tensor;
use crate::net::{NetConfig, ObsEncoder};
use crate::provenance::{ColumnError, PoseError};
use crate::symmetry::{augment_point, augment_pose};

/// Pose targets per frame: agent x, y, then block and goal x, y (world / 256 − 1),
/// cos θ, sin θ.
const POSE_DIM: usize = 10;
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
pub(crate) enum Targets<'a> {
    PushT { block: &'a [[f32; 3]], goal: &'a [[f32; 3]] },
    Columns { names: &'a [String], values: &'a [f32], mean: Vec<f32>, std: Vec<f32> },
}

impl<'a> Targets<'a> {
    /// The targets of `demos`, columns standardised over the steps `train`; `None` when the
    /// demonstrations carry no labels.
    pub(crate) fn of(demos: &'a Demos, train: &[usize]) -> Option<Self> {
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
    pub(crate) fn dim(&self) -> usize {
        match self {
            Targets::PushT { .. } => POSE_DIM,
            Targets::Columns { names, .. } => names.len(),
        }
    }

    /// Symmetries frames may be mapped through (labels mapped alike).
    pub(crate) fn symmetries(&self) -> u64 {
        match self {
            Targets::PushT { .. } => 8,
            Targets::Columns { .. } => 1,
        }
    }

    /// The regression target of demonstration step `i` seen through symmetry `k`.
    pub(crate) fn at(&self, demos: &Demos, i: usize, k: u8) -> Vec<f32> {
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

/// Up to 512 evenly spaced steps of `steps`, and the probe's outputs on their frames
/// (`dim` per step).
pub(crate) fn predict(probe: &PoseProbe, demos: &Demos, steps: &[usize], s: usize) -> (Vec<usize>, Vec<f32>) {
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
pub(crate) fn pose_error(
    probe: &PoseProbe,
    targets: &Targets,
    demos: &Demos,
    steps: &[usize],
    s: usize,
) -> PoseError {
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
pub(crate) fn column_error(
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
