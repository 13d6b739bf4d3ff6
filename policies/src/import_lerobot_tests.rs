//! The LeRobot import against PyTorch: fixtures written by `scripts/fixtures/lerobot_policy.py`
//! (evalharness's own re-implementation; checked outside the project against LeRobot 0.6.2's own
//! `DiffusionModel` at ResNet base 64: the same 213 names and shapes, identical conditioning and
//! noise prediction), reduced to ResNet base 16, 4 keypoints and U-Net levels 16/32/64, in both
//! of LeRobot's layouts (statistics in `model.safetensors`, or in the preprocessor's file), and
//! with torchvision's BatchNorms (`pretrained_model_bn`, `use_group_norm: false`), and with
//! LeRobot 0.4's antialiased resize before the crop (`pretrained_model_resize`).

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};

use super::*;
use crate::imported_policy::{Prediction, Sampler, ddim_sample, ddpm_sample, replayed, unet_out};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/lerobot_policy").join(name)
}

fn io(k: &str) -> Vec<f32> {
    io_of("io.safetensors", k)
}

fn io_of(file: &str, k: &str) -> Vec<f32> {
    let src = SafeSource::open(&fixture(file)).unwrap_or_else(|e| panic!("{e}"));
    let n = src.shapes()[k].iter().product();
    src.f32s(k, &[n], true).unwrap_or_else(|e| panic!("{e}"))
}

fn max_abs(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

/// The fixture's frames (uint8 `[2, 2, 96, 96, 3]`) as `[4, 3, 96, 96]` in [0, 1].
fn frames01(device: &Device) -> Tensor<4> {
    let src = SafeSource::open(&fixture("io.safetensors")).unwrap_or_else(|e| panic!("{e}"));
    let f = src.u8s("frames").unwrap_or_else(|e| panic!("{e}"));
    let frames: Vec<&[u8]> = f.chunks(96 * 96 * 3).collect();
    nn::frames::frames_to_tensor(&frames, 96, device) * 0.5 + 0.5
}

/// The imported U-Net's noise prediction for the fixture's two `[16, 2]` sequences `x` at step
/// `t`, given their conditioning `cond`.
fn eps_of(p: &LeRobotPolicy, cond: &[f32], x: &[f32], t: usize) -> Vec<f32> {
    unet_out(&p.net, cond, x, [2, 16, 2], t)
}

#[test]
fn both_layouts_import_and_predict_what_pytorch_predicts() {
    let device = Device::flex();
    for folder in ["pretrained_model", "pretrained_model_processors"] {
        let p = import(&fixture(folder), &device).unwrap_or_else(|e| panic!("{folder}: {e}"));
        assert_eq!(p.tensors, 212, "{folder}: every weight but the grid");
        assert_eq!(
            (p.cfg.resnet_base, p.cfg.pool, p.cfg.crop),
            (16, Pool::SpatialSoftmax { keypoints: 4, features: None }, Some(84))
        );
        assert_eq!((p.cfg.inference_steps, p.cfg.net.feature_dim, p.cfg.position_first), (Some(10), 8, true));
        // State min-max normalised as LeRobot does, with its statistics.
        let state = io("state"); // [2, 2, 2] raw
        let pos: Vec<f32> =
            state.chunks(2).flat_map(|s| p.norm.agent_pos.normalise(s).collect::<Vec<_>>()).collect();
        let pos = Tensor::from_data(TensorData::new(pos, [2, 2, 2]), &device);
        let cond = p.net.obs_cond(frames01(&device), pos);
        let cond = cond.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default();
        let d = max_abs(&cond, &io("cond"));
        assert!(d <= 1e-5, "{folder}: conditioning differs from PyTorch by {d}");
        let x = Tensor::from_data(TensorData::new(io("x"), [2, 16, 2]), &device);
        let c = Tensor::from_data(TensorData::new(io("cond"), [2, cond.len() / 2]), &device);
        let eps = p.net.unet.forward(x, Tensor::from_floats([3.0, 77.0], &device), c);
        let eps = eps.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default();
        let d = max_abs(&eps, &io("eps"));
        assert!(d <= 1e-5, "{folder}: noise prediction differs from PyTorch by {d}");
    }
}

/// The conditioning of the fixture's frames and states by `p`, as `[b, cond]` values.
fn cond_by(p: &LeRobotPolicy, device: &Device) -> Vec<f32> {
    let state = io("state"); // [2, 2, 2] raw
    let pos: Vec<f32> =
        state.chunks(2).flat_map(|s| p.norm.agent_pos.normalise(s).collect::<Vec<_>>()).collect();
    let pos = Tensor::from_data(TensorData::new(pos, [2, 2, 2]), device);
    let cond = p.net.obs_cond(frames01(device), pos);
    cond.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default()
}

#[test]
fn a_batch_norm_backbone_is_folded_and_predicts_what_pytorch_predicts() {
    // `use_group_norm: false` (LeRobot with `pretrained_backbone_weights`): torchvision's
    // BatchNorms in eval mode, each with running statistics and affine weights far from the
    // identity, folded into the convolutions at import.
    let device = Device::flex();
    let p = import(&fixture("pretrained_model_bn"), &device).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(p.cfg.backbone_norm, BackboneNorm::FoldedBatch);
    // 20 convolutions with their biases (the stem, 16 in the blocks, 3 projections) stand for 20
    // convolutions and 20 BatchNorms (4 tensors each, the step counter unread); the head and
    // the U-Net as in the GroupNorm fixture (212 − 20 convs − 40 GroupNorm tensors = 152).
    assert_eq!(p.tensors, 152 + 40, "every weight placed");
    let d = max_abs(&cond_by(&p, &device), &io_of("io_bn.safetensors", "cond"));
    assert!(d <= 1e-5, "conditioning differs from PyTorch by {d}");
    let eps = unet_out(&p.net, &io_of("io_bn.safetensors", "cond"), &io("x"), [2, 16, 2], 3);
    // `eps` was written for t = [3, 77]: compare the first sequence, at t = 3.
    let d = max_abs(&eps[..32], &io_of("io_bn.safetensors", "eps")[..32]);
    assert!(d <= 1e-5, "noise prediction differs from PyTorch by {d}");
    // The folded backbone is recorded; a GroupNorm one leaves policy.json as it was.
    assert!(serde_json::to_string(&p.cfg).unwrap().contains("\"backbone_norm\":\"folded-batch\""));
    let gn = import(&fixture("pretrained_model"), &device).unwrap_or_else(|e| panic!("{e}"));
    assert!(!serde_json::to_string(&gn.cfg).unwrap().contains("backbone_norm"));
}

#[test]
fn a_resize_shape_resizes_with_antialiasing_then_crops_as_pytorch_does() {
    // `resize_shape` [72, 72] with `crop_ratio` 0.9 (LeRobot 0.4 on): 96² frames resized to 72²
    // with torchvision's antialiased bilinear, then centre-cropped to ⌊72 · 0.9⌋ = 64.
    let device = Device::flex();
    let p = import(&fixture("pretrained_model_resize"), &device).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((p.cfg.input_size, p.cfg.antialias, p.cfg.crop), (Some(72), true, Some(64)));
    let d = max_abs(&cond_by(&p, &device), &io_of("io_resize.safetensors", "cond"));
    assert!(d <= 1e-5, "conditioning differs from PyTorch by {d}");
    let eps = unet_out(&p.net, &io_of("io_resize.safetensors", "cond"), &io("x"), [2, 16, 2], 3);
    let d = max_abs(&eps[..32], &io_of("io_resize.safetensors", "eps")[..32]);
    assert!(d <= 1e-5, "noise prediction differs from PyTorch by {d}");
    // The same network resizing without antialiasing reads other features: the setting matters.
    let mut plain = p.cfg.clone();
    plain.antialias = false;
    let mut net = ImportedNet::new(&plain, &device);
    net = net.load_record(p.net.clone().into_record());
    let state = io("state");
    let pos: Vec<f32> =
        state.chunks(2).flat_map(|s| p.norm.agent_pos.normalise(s).collect::<Vec<_>>()).collect();
    let cond = net.obs_cond(frames01(&device), Tensor::from_data(TensorData::new(pos, [2, 2, 2]), &device));
    let cond = cond.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default();
    assert!(max_abs(&cond, &io_of("io_resize.safetensors", "cond")) > 1e-3);
    // Recorded in policy.json; a policy without a resize leaves it as it was.
    assert!(serde_json::to_string(&p.cfg).unwrap().contains("\"antialias\":true"));
    let gn = import(&fixture("pretrained_model"), &device).unwrap_or_else(|e| panic!("{e}"));
    assert!(!serde_json::to_string(&gn.cfg).unwrap().contains("antialias"));
}

#[test]
fn a_backbone_whose_norm_disagrees_with_the_config_is_refused_by_key() {
    let device = Device::flex();
    let tmp = tempfile::tempdir().unwrap();
    // GroupNorm weights under `use_group_norm: false`: the first BatchNorm statistic is missing.
    let dir = edited(tmp.path(), |v| v["use_group_norm"] = serde_json::json!(false));
    let err = import(&dir, &device).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("diffusion.rgb_encoder.backbone.1.running_mean"), "{err}");
    // BatchNorm weights under `use_group_norm: true`: their running statistics have no place.
    let out = tmp.path().join("bn_as_gn");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::copy(fixture("pretrained_model_bn/model.safetensors"), out.join("model.safetensors")).unwrap();
    std::fs::copy(fixture("pretrained_model/config.json"), out.join("config.json")).unwrap();
    let err = import(&out, &device).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("running_mean") && err.contains("model.safetensors"), "{err}");
}

#[test]
fn one_ddpm_step_with_injected_noise_is_pytorchs() {
    // One of the ten leading steps, t = 80 to 70, given PyTorch's noise prediction there and its
    // noise z: the step's arithmetic alone (x0 clipped, the posterior mean, "fixed_small"
    // variance), as the fixture script computes it with diffusers' formulas.
    let (mut x, eps, z) = (io("x"), io("eps80"), io("z"));
    crate::imported_policy::ddpm_step(&mut x, &eps, 80, Some(70), &crate::diffusion::alphas_cumprod(100), &z);
    let d = max_abs(&x, &io("step80"));
    assert!(d <= 1e-6, "one DDPM step differs from PyTorch's by {d}");
    // The networks' own prediction there is PyTorch's within 1e-5.
    let p = import(&fixture("pretrained_model"), &Device::flex()).unwrap_or_else(|e| panic!("{e}"));
    assert!(max_abs(&eps_of(&p, &io("cond"), &io("x"), 80), &eps) <= 1e-5);
}

#[test]
fn ten_leading_ddpm_steps_with_pytorchs_noise_give_pytorchs_actions() {
    let device = Device::flex();
    let p = import(&fixture("pretrained_model"), &device).unwrap_or_else(|e| panic!("{e}"));
    let cond = io("cond"); // noises [10, 2, 16, 2]
    let ac = crate::diffusion::alphas_cumprod(100);
    let got =
        ddpm_sample(io("x"), &ac, &p.cfg.timesteps(), |x, t| eps_of(&p, &cond, x, t), replayed(io("noises")));
    let d = max_abs(&got, &io("actions"));
    assert!(d <= 1e-4, "DDPM differs from PyTorch's by {d}");
}

#[test]
fn a_ddim_policy_imports_and_its_ten_steps_give_pytorchs_actions() {
    // `noise_scheduler_type: DDIM`: diffusers' DDIMScheduler as LeRobot configures it. The
    // fixture's `actions_ddim` come from the fixture script's DDIM loop, which matched
    // diffusers 0.42.1's DDIMScheduler to 1.2e-6 on the same network (checked outside the
    // project); DDIM draws no noise after the initial `x`.
    let device = Device::flex();
    let tmp = tempfile::tempdir().unwrap();
    let dir = edited(tmp.path(), |v| v["noise_scheduler_type"] = serde_json::json!("DDIM"));
    let p = import(&dir, &device).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(p.cfg.sampler, Sampler::Ddim);
    assert_eq!(p.cfg.timesteps(), [90, 80, 70, 60, 50, 40, 30, 20, 10, 0]);
    let cond = io("cond");
    let ac = crate::diffusion::alphas_cumprod(100);
    let got = ddim_sample(io("x"), &ac, &p.cfg.timesteps(), |x, t| eps_of(&p, &cond, x, t));
    let d = max_abs(&got, &io("actions_ddim"));
    assert!(d <= 1e-4, "DDIM differs from PyTorch's by {d}");
    // Not the DDPM result: the sampler is used, not only recorded.
    assert!(max_abs(&got, &io("actions")) > 1e-2);
    // A DDPM import records nothing new: policies imported before DDIM read the same.
    let ddpm = import(&fixture("pretrained_model"), &device).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(ddpm.cfg.sampler, Sampler::Ddpm);
    assert!(!serde_json::to_string(&ddpm.cfg).unwrap().contains("sampler"));
}

#[test]
fn a_sample_predicting_policy_steps_as_diffusers_does() {
    // `prediction_type: sample`: the U-Net's output is x0; the noise the step uses is derived
    // from it before clipping. The fixture's `actions_sample` and `actions_ddim_sample` are the
    // script's DDPM and DDIM loops reading the same network that way.
    let device = Device::flex();
    let tmp = tempfile::tempdir().unwrap();
    let cond = io("cond");
    let ac = crate::diffusion::alphas_cumprod(100);
    for (sched, want) in [("DDPM", "actions_sample"), ("DDIM", "actions_ddim_sample")] {
        let dir = edited(tmp.path(), |v| {
            v["prediction_type"] = serde_json::json!("sample");
            v["noise_scheduler_type"] = serde_json::json!(sched);
        });
        let p = import(&dir, &device).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(p.cfg.prediction, Prediction::Sample);
        let eps = |x: &[f32], t: usize| p.cfg.prediction.noise(x, eps_of(&p, &cond, x, t), ac[t]);
        let got = if sched == "DDPM" {
            ddpm_sample(io("x"), &ac, &p.cfg.timesteps(), eps, replayed(io("noises")))
        } else {
            ddim_sample(io("x"), &ac, &p.cfg.timesteps(), eps)
        };
        let d = max_abs(&got, &io(want));
        assert!(d <= 1e-4, "{sched}: differs from PyTorch's by {d}");
        // Reading the output as noise gives other actions: the setting is used.
        let other = if sched == "DDPM" { "actions" } else { "actions_ddim" };
        assert!(max_abs(&got, &io(other)) > 1e-2, "{sched}");
    }
}

/// A copy of the legacy fixture folder with `config.json` edited by `edit`.
fn edited(dir: &Path, edit: impl Fn(&mut serde_json::Value)) -> PathBuf {
    let out = dir.join("pm");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::copy(fixture("pretrained_model/model.safetensors"), out.join("model.safetensors")).unwrap();
    let text = std::fs::read_to_string(fixture("pretrained_model/config.json")).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    edit(&mut v);
    std::fs::write(out.join("config.json"), v.to_string()).unwrap();
    out
}

#[test]
fn unsupported_settings_and_missing_statistics_are_refused_by_name() {
    let device = Device::flex();
    let tmp = tempfile::tempdir().unwrap();
    for (field, value) in [
        ("noise_scheduler_type", serde_json::json!("PNDM")),
        ("prediction_type", serde_json::json!("v_prediction")),
        ("vision_backbone", serde_json::json!("resnet34")),
        ("resize_shape", serde_json::json!([72, 64])),
        ("crop_ratio", serde_json::json!(1.5)),
    ] {
        let dir = edited(tmp.path(), |v| v[field] = value.clone());
        let err = import(&dir, &device).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(err.contains(field) && err.contains("config.json"), "{field}: {err}");
    }
    // The processor layout without its statistics file.
    let dir = tmp.path().join("nostats");
    std::fs::create_dir_all(&dir).unwrap();
    for f in ["config.json", "model.safetensors"] {
        std::fs::copy(fixture("pretrained_model_processors").join(f), dir.join(f)).unwrap();
    }
    let err = import(&dir, &device).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("normalisation statistics"), "{err}");
}
