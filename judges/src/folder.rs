//! A learned judge of imagined frames: a small CNN that reads one frame and
//! estimates the raw score the task would give the scene it shows (Push-T: the
//! goal coverage; robomimic: the probability of success).
//!
//! It implements [`harness::judge::Judge`], so `rank --judge DIR` can score the
//! imagined branch with it instead of the task's hand-written pixel rules, and the
//! engine reports its error against the exact score on the simulator branch's real
//! frames in every run, as it does for any judge. It is trained by
//! `evalharness train judge` ([`crate::train`]) on simulator frames labelled
//! with the exact score.
//!
//! The network is the diffusion policy's frame encoder ([`ObsEncoder`]: 4 stride-2
//! convolutions with GroupNorm residual blocks, a linear layer to `feature_dim`)
//! and a linear head to one logit; the score is its sigmoid. Inference runs the
//! encoder on the project's CPU kernels ([`CpuEncoder`]) on the Flex device.
//!
//! A judge folder holds `judge.json` ([`JudgeFile`]) and `model.bpk` (f16 weights).

use std::path::Path;

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::{Device, Tensor};
use harness::judge::Judge;
use serde::{Deserialize, Serialize};

use nn::frames::{frames_to_tensor, frames_to_vec};
use policies::cpu_encoder::CpuEncoder;
use policies::dir::{load_weights, save_f16};
use policies::net::{NetConfig, ObsEncoder};

use crate::error::JudgeError;
use crate::metrics::JudgeMetrics;
use crate::pose::{GpcPose, PoseNet};
use crate::provenance::JudgeProvenance;
use crate::rule::ColourHeight;

/// The judge's network: frame encoder and a one-logit head.
#[derive(Module, Debug)]
pub struct JudgeNet {
    /// The frame encoder.
    pub encoder: ObsEncoder,
    /// Features to one logit.
    pub head: Linear,
}

impl JudgeNet {
    /// Fresh weights for `cfg` (its image size, encoder width and feature size).
    pub fn new(cfg: &NetConfig, device: &Device) -> Self {
        Self {
            encoder: ObsEncoder::new(cfg, device),
            head: LinearConfig::new(cfg.feature_dim, 1).init(device),
        }
    }

    /// # Shapes
    /// `[n, 3, s, s]` in [-1, 1] → `[n, 1]` logits
    pub fn forward(&self, frames: Tensor<4>) -> Tensor<2> {
        self.head.forward(self.encoder.forward(frames))
    }
}

/// What a judge was trained to read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Label {
    /// Push-T's goal coverage in [0, 1] (`data/coverage`).
    Coverage,
    /// robomimic's success, 0 or 1 (`data/success`).
    Success,
}

impl Label {
    /// The per-step dataset array holding the label.
    pub fn array(self) -> &'static str {
        match self {
            Self::Coverage => "coverage",
            Self::Success => "success",
        }
    }
}

/// `judge.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JudgeFile {
    /// `"learned"` (a network in `model.bpk`), `"colour_height"` (the hand-written
    /// [`ColourHeight`] rule in `rule`, no weights) or `"gpc_pose"` (GPC's reward
    /// predictors in `xy.bpk` and `angle.bpk`, which read the block's pose).
    pub kind: String,
    /// The encoder's configuration (image size, width, feature size; the rest unused).
    /// A rule's folder uses only its image size.
    pub net: NetConfig,
    /// The hand-written rule of a `"colour_height"` judge.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rule: Option<ColourHeight>,
    /// The backbones' base width of a `"gpc_pose"` judge (GPC's reward predictors,
    /// [`crate::pose`]; torchvision's 64).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose_base: Option<usize>,
    /// What it estimates.
    pub label: Label,
    /// The raw value above which an episode succeeds (0.95 coverage, 0.5 success).
    pub threshold: f64,
    /// Judged frames in a row that must show success before an imagined episode
    /// counts it ([`Judge::persist`]; 1 in judges written before the rule existed).
    #[serde(default = "one_frame")]
    pub persist_frames: usize,
    /// Training steps done.
    pub steps: u64,
    /// Its reading of the held-out episodes' frames.
    pub heldout: JudgeMetrics,
    /// How it was made: command, dataset and its fingerprint, seed, commit.
    pub provenance: JudgeProvenance,
}

fn one_frame() -> usize {
    1
}

/// Writes a judge folder (`judge.json`, and `model.bpk` for a network), each file
/// atomically.
///
/// # Errors
/// [`JudgeError`] naming the file that could not be written.
pub fn write_judge(dir: &Path, net: Option<&JudgeNet>, file: &JudgeFile) -> Result<(), JudgeError> {
    std::fs::create_dir_all(dir).map_err(|source| JudgeError::Io { path: dir.into(), source })?;
    if let Some(net) = net {
        let weights = dir.join("model.bpk");
        let tmp = dir.join(".model.bpk.tmp");
        save_f16(net, &tmp).map_err(|source| JudgeError::Weights { path: weights.clone(), source })?;
        std::fs::rename(&tmp, &weights).map_err(|source| JudgeError::Io { path: weights, source })?;
    }
    let text = serde_json::to_string_pretty(file).unwrap_or_default() + "\n";
    Ok(harness::runfile::write_atomic(&dir.join("judge.json"), &text)?)
}

/// A judge folder, for inference: a trained network or a hand-written rule.
pub struct FrameJudge {
    /// Its `judge.json`.
    pub file: JudgeFile,
    /// The network (none for a rule).
    net: Option<JudgeNet>,
    /// The encoder on direct CPU kernels (Flex device), with the head's weights.
    cpu: Option<(CpuEncoder, Vec<f32>, f32)>,
    /// GPC's pose regressors (a `"gpc_pose"` judge).
    pose: Option<GpcPose>,
    device: Device,
}

impl FrameJudge {
    /// Loads a judge folder.
    ///
    /// # Errors
    /// [`JudgeError`] naming the file for a missing or invalid `judge.json`,
    /// a rule without its parameters or of another frame size, or weights that are
    /// missing, truncated or do not match it.
    pub fn load(dir: &Path, device: &Device) -> Result<Self, JudgeError> {
        let path = dir.join("judge.json");
        let err = |what: String| JudgeError::Invalid { path: path.clone(), what };
        let text =
            std::fs::read_to_string(&path).map_err(|source| JudgeError::Io { path: path.clone(), source })?;
        let file: JudgeFile =
            serde_json::from_str(&text).map_err(|source| JudgeError::File { path: path.clone(), source })?;
        fn weights<M: Module>(net: M, dir: &Path, name: &str) -> Result<M, JudgeError> {
            let path = dir.join(name);
            load_weights(net, &path).map_err(|source| JudgeError::Weights { path, source })
        }
        match (file.kind.as_str(), file.rule) {
            ("learned", _) => {
                let net = weights(JudgeNet::new(&file.net, device), dir, "model.bpk")?;
                Ok(Self::new(file, net, device))
            }
            ("gpc_pose", _) => {
                let base = file.pose_base.ok_or_else(|| err("kind \"gpc_pose\" without pose_base".into()))?;
                let net = |name: &str| weights(PoseNet::new(base, device), dir, name);
                let pose = GpcPose::new(net("xy.bpk")?, net("angle.bpk")?, device);
                Ok(Self { file, net: None, cpu: None, pose: Some(pose), device: device.clone() })
            }
            ("colour_height", Some(r)) if r.image_size == file.net.image_size => Ok(Self::rule(file)),
            ("colour_height", Some(r)) => Err(err(format!(
                "rule.image_size {} differs from net.image_size {}",
                r.image_size, file.net.image_size
            ))),
            ("colour_height", None) => Err(err("kind \"colour_height\" without a rule".into())),
            (k, _) => {
                Err(err(format!("kind \"{k}\", expected \"learned\", \"colour_height\" or \"gpc_pose\"")))
            }
        }
    }

    /// A hand-written rule's judge (`file.rule`; no network).
    pub fn rule(file: JudgeFile) -> Self {
        Self { file, net: None, cpu: None, pose: None, device: Device::flex() }
    }

    /// Wraps trained weights.
    pub fn new(file: JudgeFile, net: JudgeNet, device: &Device) -> Self {
        let cpu = (*device == Device::flex())
            .then(|| {
                let enc = CpuEncoder::new(&net.encoder)
                    .inspect_err(|e| tracing::warn!("judge: burn's encoder kept: {e}"))
                    .ok()?;
                let w = net.head.weight.val().into_data().convert::<f32>().try_into_vec::<f32>().ok()?;
                let b = match &net.head.bias {
                    Some(b) => b.val().into_data().convert::<f32>().try_into_vec::<f32>().ok()?[0],
                    None => 0.0,
                };
                Some((enc, w, b))
            })
            .flatten();
        Self { file, net: Some(net), cpu, pose: None, device: device.clone() }
    }

    /// Its network (inference device); none for a rule.
    pub fn net(&self) -> Option<&JudgeNet> {
        self.net.as_ref()
    }

    /// The frame side it reads.
    pub fn image_size(&self) -> usize {
        self.file.net.image_size
    }

    /// Estimates for `frames` (each `s x s x 3` bytes), in [0, 1]. A `"gpc_pose"` judge reads
    /// poses, not scores ([`Judge::pose`]): its score needs the episode's goal, so here NaN.
    pub fn score_frames(&self, frames: &[&[u8]]) -> Vec<f64> {
        let s = self.image_size();
        if self.pose.is_some() {
            return vec![f64::NAN; frames.len()];
        }
        // A rule's folder has no network (`load` checks that it has the rule).
        let Some(net) = &self.net else {
            return frames.iter().map(|f| self.file.rule.map_or(f64::NAN, |r| r.score(f))).collect();
        };
        let logits: Vec<f32> = match &self.cpu {
            Some((enc, w, b)) => {
                let feat = enc.forward(&frames_to_vec(frames, s), frames.len(), s); // [n, f]
                let f = w.len();
                feat.chunks(f).map(|x| x.iter().zip(w).map(|(a, c)| a * c).sum::<f32>() + b).collect()
            }
            None => net
                .forward(frames_to_tensor(frames, s, &self.device))
                .into_data()
                .convert::<f32>()
                .try_into_vec::<f32>()
                .unwrap_or_default(),
        };
        // A non-finite logit (non-finite weights) is not a certainty: it scores NaN,
        // which the engine refuses, where the sigmoid would read +inf as a sure success.
        logits
            .into_iter()
            .map(|z| if z.is_finite() { 1.0 / (1.0 + (-f64::from(z)).exp()) } else { f64::NAN })
            .collect()
    }
}

impl Judge for FrameJudge {
    fn score(&self, frame: &[u8]) -> f64 {
        let s = self.image_size();
        if frame.len() != s * s * 3 {
            // The engine checks the world model's frame size against the judge's at
            // start-up; a frame of another size here is a bug, and scores nothing.
            return f64::NAN;
        }
        self.score_frames(&[frame])[0]
    }
    fn persist(&self) -> usize {
        self.file.persist_frames.max(1)
    }
    fn pose(&self, frame: &[u8]) -> Option<Vec<f64>> {
        let s = self.image_size();
        let pose = self.pose.as_ref()?;
        if frame.len() != s * s * 3 {
            return Some(vec![f64::NAN; 3]);
        }
        pose.poses(&[frame], s).first().map(|p| p.to_vec())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(net: NetConfig) -> JudgeFile {
        JudgeFile {
            kind: "learned".into(),
            net,
            label: Label::Coverage,
            rule: None,
            pose_base: None,
            threshold: 0.95,
            persist_frames: 1,
            steps: 0,
            heldout: JudgeMetrics::default(),
            provenance: JudgeProvenance::default(),
        }
    }

    #[test]
    fn cpu_kernels_and_burn_agree_and_a_saved_judge_loads() {
        let device = Device::flex();
        let cfg = NetConfig::new().with_encoder_width(8).with_feature_dim(16);
        let net = JudgeNet::new(&cfg, &device);
        let frames: Vec<Vec<u8>> =
            (0..3).map(|k| (0..96 * 96 * 3).map(|i| ((i * 7 + k * 31) % 256) as u8).collect()).collect();
        let refs: Vec<&[u8]> = frames.iter().map(Vec::as_slice).collect();
        let burn: Vec<f64> = net
            .forward(frames_to_tensor(&refs, 96, &device))
            .into_data()
            .convert::<f32>()
            .try_into_vec::<f32>()
            .unwrap()
            .into_iter()
            .map(|z| 1.0 / (1.0 + (-f64::from(z)).exp()))
            .collect();
        let judge = FrameJudge::new(file(cfg.clone()), net.clone(), &device);
        assert!(judge.cpu.is_some());
        let cpu = judge.score_frames(&refs);
        for (a, b) in cpu.iter().zip(&burn) {
            assert!((a - b).abs() < 1e-4, "{cpu:?} vs {burn:?}");
        }
        // One frame alone: the same estimate up to the batched products' rounding.
        assert!((judge.score(&frames[1]) - cpu[1]).abs() < 1e-6);
        assert!(judge.score(&[0u8; 12]).is_nan());
        // Saved in f16 and loaded back: the same estimates to f16 rounding.
        let dir = std::env::temp_dir().join(format!("evalharness-judge-{}", std::process::id()));
        write_judge(&dir, Some(&net), &file(cfg)).unwrap();
        let back = FrameJudge::load(&dir, &device).unwrap();
        for (a, b) in back.score_frames(&refs).iter().zip(&cpu) {
            assert!((a - b).abs() < 1e-2, "{a} vs {b}");
        }
        // A rule's folder: no weights; a rule of another frame size, or none, is refused.
        let rule = crate::rule::ColourHeight::lift_red();
        let mut f = JudgeFile { kind: "colour_height".into(), rule: Some(rule), ..file(NetConfig::new()) };
        let rdir = dir.join("rule");
        write_judge(&rdir, None, &f).unwrap();
        assert!(!rdir.join("model.bpk").exists());
        let back = FrameJudge::load(&rdir, &device).unwrap();
        // A 96 x 96 white frame has no red pixels: 0.
        assert_eq!((back.score(&[255u8; 96 * 96 * 3]), back.net().is_none()), (0.0, true));
        f.net = NetConfig::new().with_image_size(64);
        write_judge(&rdir, None, &f).unwrap();
        let e = FrameJudge::load(&rdir, &device).err().unwrap().to_string();
        assert!(e.contains("rule.image_size 96 differs from net.image_size 64"), "{e}");
        f.rule = None;
        write_judge(&rdir, None, &f).unwrap();
        let e = FrameJudge::load(&rdir, &device).err().unwrap().to_string();
        assert!(e.contains("without a rule"), "{e}");
        std::fs::write(dir.join("model.bpk"), b"truncated").unwrap();
        let e = FrameJudge::load(&dir, &device).err().unwrap().to_string();
        assert!(e.contains("model.bpk") && e.contains("evalharness-judge"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
