//! GPC's Push-T reward predictors as a judge: two ResNet-18 regressors read the T block's
//! pose from a frame (one its position in world units, one (cos θ, sin θ)), and the task's
//! judge of the episode turns the pose into the exact goal coverage
//! ([`harness::judge::Judge::score_pose`]), as GPC's evaluation places the predicted pose in
//! its scene and intersects it with the goal.
//!
//! `evalharness import judge --format gpc-reward-predictor --xy FILE --angle FILE` reads the
//! two `state_dict` files (`resnet18.{0..7}.*` then `mlp.{1,3,5}.*`, 126 tensors each), folds
//! every BatchNorm into the convolution before it ([`policies::resnet`]) and writes a judge folder:
//! `judge.json` (kind `gpc_pose`) with `xy.bpk` and `angle.bpk` (f32).
//!
//! Input: the frame in [0, 1] (bytes / 255), as the official code feeds it.

use std::path::Path;

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};
use nn::ImportError;
use nn::import::place::{place_all, shapes, transpose};
use nn::import::tensors::Source;
use policies::cpu_resnet::CpuResNet18;
use policies::cpu_unet::Products;
use policies::diffusion::cpu_kernels_on;
use policies::resnet::{ConvSite, ResNet18, batch_norm_sites, fold_batch_norm};

use crate::error::JudgeError;

/// One reward predictor: ResNet-18 features, then 512 → 256 → 128 → 2 with ReLUs (8·base
/// → 256 at another base width).
#[derive(Module, Debug)]
pub struct PoseNet {
    /// The backbone (BatchNorms folded).
    pub resnet: ResNet18,
    /// 512 → 256.
    pub l1: Linear,
    /// 256 → 128.
    pub l2: Linear,
    /// 128 → 2.
    pub l3: Linear,
}

impl PoseNet {
    /// Fresh weights at the backbone's base width `base` (torchvision's: 64).
    pub fn new(base: usize, device: &Device) -> Self {
        Self {
            resnet: ResNet18::new(base, device),
            l1: LinearConfig::new(8 * base, 256).init(device),
            l2: LinearConfig::new(256, 128).init(device),
            l3: LinearConfig::new(128, 2).init(device),
        }
    }

    /// # Shapes
    /// `[n, 3, h, w]` in [0, 1] → `[n, 2]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<2> {
        self.head(self.resnet.forward(x))
    }

    /// The MLP on the backbone's pooled features.
    ///
    /// # Shapes
    /// `[n, 8 base]` → `[n, 2]`
    pub fn head(&self, features: Tensor<2>) -> Tensor<2> {
        let h = relu(self.l1.forward(features));
        self.l3.forward(relu(self.l2.forward(h)))
    }
}

/// The two predictors.
pub struct GpcPose {
    /// Position (world units).
    pub xy: PoseNet,
    /// (cos θ, sin θ), unnormalised.
    pub angle: PoseNet,
    /// The two backbones on the project's CPU kernels (on the Flex device, unless
    /// `EVALHARNESS_POLICY_KERNELS=burn`), with the imported policies' same-bits products.
    cpu: Option<[CpuResNet18; 2]>,
    device: Device,
}

impl GpcPose {
    /// Wraps two predictors on `device`.
    pub fn new(xy: PoseNet, angle: PoseNet, device: &Device) -> Self {
        let products = Products::or_env(Products::Chain);
        let cpu = cpu_kernels_on(device)
            .then(|| {
                let both = CpuResNet18::folded(&xy.resnet, products)
                    .and_then(|a| Ok([a, CpuResNet18::folded(&angle.resnet, products)?]));
                both.inspect_err(|e| tracing::warn!("the reward predictors keep burn's backbone: {e}"))
            })
            .and_then(Result::ok);
        Self { xy, angle, cpu, device: device.clone() }
    }

    /// Block poses `[x, y, θ]` (θ = atan2(sin, cos) in [0, 2π)) of `frames`, each
    /// `s × s × 3` bytes.
    pub fn poses(&self, frames: &[&[u8]], s: usize) -> Vec<[f64; 3]> {
        let x = nn::frames::frames_to_tensor(frames, s, &self.device) * 0.5 + 0.5; // [n, 3, s, s] in [0, 1]
        let v = |t: Tensor<2>| t.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default();
        let values = |x: &Tensor<4>| x.clone().into_data().convert::<f32>().try_into_vec::<f32>().ok();
        let (xy, cs) = match self.cpu.as_ref().and_then(|cpu| Some((cpu, values(&x)?))) {
            Some(([cpu_xy, cpu_angle], xs)) => {
                // Both backbones on the CPU kernels, then each predictor's MLP on its features.
                let [n, _, h, w] = x.dims();
                let head = |net: &PoseNet, cpu: &CpuResNet18| {
                    let (f, c) = cpu.pooled(&xs, n, (h, w));
                    v(net.head(Tensor::from_data(TensorData::new(f, [n, c]), &self.device)))
                };
                (head(&self.xy, cpu_xy), head(&self.angle, cpu_angle))
            }
            None => (v(self.xy.forward(x.clone())), v(self.angle.forward(x))),
        };
        xy.chunks_exact(2)
            .zip(cs.chunks_exact(2))
            .map(|(p, c)| {
                let theta = f64::from(c[1]).atan2(f64::from(c[0])).rem_euclid(std::f64::consts::TAU);
                [f64::from(p[0]), f64::from(p[1]), theta]
            })
            .collect()
    }
}

/// Reads one official reward predictor (`state_dict`, 126 tensors), BatchNorms folded; the
/// backbone's base width is read from the stem (`resnet18.0.weight`). Returns it with the base.
///
/// # Errors
/// [`ImportError`] naming the file and key for a missing, unexpected, mis-shaped, non-f32 or
/// non-finite tensor.
pub fn import_pose_net(path: &Path, device: &Device) -> Result<(PoseNet, usize), ImportError> {
    let src = Source::open(path, None, "")?;
    let base = match src.shapes().get("resnet18.0.weight").map(Vec::as_slice) {
        Some(&[b, 3, 7, 7]) if b > 0 => b,
        Some(s) => {
            let (found, expected) = (s.to_vec(), vec![64, 3, 7, 7]);
            return Err(ImportError::Shape {
                path: path.into(),
                key: "resnet18.0.weight".into(),
                found,
                expected,
            });
        }
        None => return Err(ImportError::Missing { path: path.into(), key: "resnet18.0.weight".into() }),
    };
    let net = PoseNet::new(base, device);
    let ours = shapes(&net);
    let mut used = std::collections::BTreeSet::new();
    let mut values = std::collections::BTreeMap::new();
    let mut take = |key: &str, shape: &[usize]| -> Result<Vec<f32>, ImportError> {
        used.insert(key.to_string());
        src.f32s(key, shape)
    };
    // conv (no bias) + BatchNorm → a conv with bias.
    let mut fold = |conv: &str, bn: &str, ours_path: &str| -> Result<(), ImportError> {
        let shape = ours[&format!("{ours_path}.weight")].clone();
        let co = shape[0];
        let mut w = take(&format!("{conv}.weight"), &shape)?;
        let g = take(&format!("{bn}.weight"), &[co])?;
        let b = take(&format!("{bn}.bias"), &[co])?;
        let m = take(&format!("{bn}.running_mean"), &[co])?;
        let var = take(&format!("{bn}.running_var"), &[co])?;
        let bias = fold_batch_norm(&mut w, &g, &b, &m, &var).map_err(|neg| ImportError::Layout {
            path: path.into(),
            what: format!("key `{bn}.running_var` is negative at channel {neg}"),
        })?;
        values.insert(format!("{ours_path}.weight"), TensorData::new(w, shape));
        values.insert(format!("{ours_path}.bias"), TensorData::new(bias, [co]));
        Ok(())
    };
    for (conv, bn, site) in batch_norm_sites() {
        let to = match site {
            ConvSite::Stem => "resnet.stem".to_string(),
            ConvSite::First(b) => format!("resnet.blocks.{b}.conv1"),
            ConvSite::Second(b) => format!("resnet.blocks.{b}.conv2"),
            ConvSite::Down(b) => format!("resnet.blocks.{b}.down"),
        };
        fold(&format!("resnet18.{conv}"), &format!("resnet18.{bn}"), &to)?;
    }
    for (i, l) in [(1, "l1"), (3, "l2"), (5, "l3")] {
        let shape = ours[&format!("{l}.weight")].clone(); // burn [in, out]
        let (din, dout) = (shape[0], shape[1]);
        let w = take(&format!("mlp.{i}.weight"), &[dout, din])?;
        values.insert(format!("{l}.weight"), TensorData::new(transpose(&w, din, dout), shape));
        values.insert(format!("{l}.bias"), TensorData::new(take(&format!("mlp.{i}.bias"), &[dout])?, [dout]));
    }
    // A BatchNorm's step counter (int64) is expected beside its statistics, and not read.
    let expected = |n: &str| {
        used.contains(n)
            || n.strip_suffix("num_batches_tracked")
                .is_some_and(|bn| used.contains(&format!("{bn}running_mean")))
    };
    let unexpected: Vec<String> = src.names().filter(|n| !expected(n)).map(str::to_string).collect();
    if !unexpected.is_empty() {
        return Err(ImportError::Unexpected { path: path.into(), keys: unexpected });
    }
    let net = place_all(net, values, path)?;
    Ok((net, base))
}

/// Imports GPC's two reward predictors (`xy`, `angle`: `state_dict` files) as a judge's
/// networks, with the base width both share.
///
/// # Errors
/// [`ImportError`] naming the file and key at fault, or [`ImportError::Layout`] when the two
/// backbones differ in width.
pub fn import_gpc(xy: &Path, angle: &Path, device: &Device) -> Result<(GpcPose, usize), ImportError> {
    let (xy_net, base) = import_pose_net(xy, device)?;
    let (angle_net, b2) = import_pose_net(angle, device)?;
    if b2 != base {
        return Err(ImportError::Layout {
            path: angle.into(),
            what: format!("backbone base width {b2}, but the xy predictor's is {base}"),
        });
    }
    Ok((GpcPose::new(xy_net, angle_net, device), base))
}

/// Writes a `"gpc_pose"` judge folder's weights (`xy.bpk`, `angle.bpk`, f32).
///
/// # Errors
/// [`JudgeError::Weights`] naming the file that could not be written.
pub fn write_pose_weights(dir: &Path, pose: &GpcPose) -> Result<(), JudgeError> {
    for (name, net) in [("xy.bpk", &pose.xy), ("angle.bpk", &pose.angle)] {
        let path = dir.join(name);
        net.clone().save_file(&path).map_err(|source| JudgeError::Weights { path, source })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fixture(name: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/gpc_reward").join(name)
    }

    #[test]
    fn imported_predictors_read_what_pytorch_reads() {
        // scripts/fixtures/gpc_reward.py: our PyTorch re-implementation at base width 8 (checked
        // there against torchvision's resnet18 at base 64: same 126 names and shapes, same
        // outputs), BatchNorm statistics off their defaults; 3 random frames and the outputs.
        let device = Device::flex();
        let (pose, base) =
            import_gpc(&fixture("reward_predictor_xy.pth"), &fixture("reward_predictor_angle.pth"), &device)
                .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(base, 8);
        let io = Source::open(&fixture("reward_io.pth"), None, "").unwrap_or_else(|e| panic!("{e}"));
        let shapes = io.shapes();
        let read = |k: &str| io.f32s(k, &shapes[k]);
        let frames_t = io.shapes()["frames"].clone();
        assert_eq!(frames_t, vec![3, 96, 96, 3]);
        // The frames are uint8: read them through the reader's raw bytes.
        let e = read("frames").err().map(|e| e.to_string()).unwrap_or_default();
        assert!(e.contains("u8"), "{e}");
        let bytes = pytorch_frames(&fixture("reward_io.pth"));
        let frames: Vec<&[u8]> = bytes.chunks(96 * 96 * 3).collect();
        let x = nn::frames::frames_to_tensor(&frames, 96, &device) * 0.5 + 0.5;
        let v = |t: Tensor<2>| t.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default();
        for (net, key) in [(&pose.xy, "xy"), (&pose.angle, "angle")] {
            let (got, want) = (v(net.forward(x.clone())), read(key).unwrap_or_else(|e| panic!("{e}")));
            let d = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
            let scale = want.iter().map(|a| a.abs()).fold(1.0f32, f32::max);
            assert!(d <= 1e-5 * scale, "{key}: max |Δ| {d} (outputs up to {scale})");
        }
        // Poses: x, y as predicted; θ = atan2(sin, cos) in [0, 2π).
        let want_xy = read("xy").unwrap_or_default();
        let want_cs = read("angle").unwrap_or_default();
        for (i, p) in pose.poses(&frames, 96).iter().enumerate() {
            assert!(
                (p[0] - f64::from(want_xy[2 * i])).abs() < 1e-2
                    && (p[1] - f64::from(want_xy[2 * i + 1])).abs() < 1e-2
            );
            let theta = f64::from(want_cs[2 * i + 1])
                .atan2(f64::from(want_cs[2 * i]))
                .rem_euclid(std::f64::consts::TAU);
            assert!((p[2] - theta).abs() < 1e-4, "{} vs {theta}", p[2]);
        }
    }

    /// The `frames` entry's bytes (uint8).
    fn pytorch_frames(path: &Path) -> Vec<u8> {
        let r = pytorch_reader::PytorchReader::new(path).unwrap_or_else(|e| panic!("{e}"));
        r.get("frames").and_then(|t| t.read().ok()).unwrap_or_default()
    }

    #[test]
    fn a_predictor_without_a_key_is_refused_naming_it() {
        let device = Device::flex();
        let e =
            import_gpc(&fixture("reward_missing_key.pth"), &fixture("reward_predictor_angle.pth"), &device)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
        assert!(
            e.contains("`resnet18.5.0.downsample.1.running_var` is missing")
                && e.contains("reward_missing_key.pth"),
            "{e}"
        );
    }
}
