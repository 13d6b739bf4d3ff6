//! The GPC policy import against PyTorch: fixtures written by `scripts/fixtures/gpc_policy.py`
//! (evalharness's own re-implementation, checked there against the official `ConditionalUnet1D`
//! and torchvision's ResNet-18 with GroupNorm: the same 208 parameters in the same order and
//! identical outputs), reduced to ResNet base 16 and U-Net levels 16/32/64.

use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor, TensorData};

use super::*;
use crate::cpu_resnet::CpuResNet18;
use crate::cpu_unet::{CpuUnet1d, Products};
use crate::imported_policy::{ImportedNet, ddpm_sample, replayed, unet_out};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/gpc_policy").join(name)
}

fn io() -> Source {
    Source::open(&fixture("policy_io.pth"), None, "").unwrap_or_else(|e| panic!("{e}"))
}

fn read(src: &Source, k: &str) -> Vec<f32> {
    let s = src.shapes()[k].clone();
    src.f32s(k, &s).unwrap_or_else(|e| panic!("{e}"))
}

fn max_abs(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

fn vec2(t: Tensor<2>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default()
}

/// The fixture's observation conditioning, computed by the imported networks.
fn cond_of(net: &ImportedNet, device: &Device) -> Vec<f32> {
    cond_on(net, device, None)
}

/// [`cond_of`] with the encoder on the CPU kernels where given.
fn cond_on(net: &ImportedNet, device: &Device, cpu: Option<&CpuResNet18>) -> Vec<f32> {
    let r = pytorch_reader::PytorchReader::new(fixture("policy_io.pth")).unwrap_or_else(|e| panic!("{e}"));
    let bytes = r.get("frames").and_then(|t| t.read().ok()).unwrap_or_default(); // [2, 2, 96, 96, 3] u8
    let frames: Vec<&[u8]> = bytes.chunks(96 * 96 * 3).collect();
    let x01 = nn::frames::frames_to_tensor(&frames, 96, device) * 0.5 + 0.5;
    let pos = Tensor::from_data(TensorData::new(read(&io(), "pos"), [2, 2, 2]), device);
    vec2(net.obs_cond_on(x01, pos, cpu))
}

#[test]
fn the_ema_weights_predict_what_pytorch_predicts() {
    let device = Device::flex();
    let p = import(&fixture("policy.pth"), GpcWeights::Ema, 96, &device).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((p.tensors, p.step), (208, Some(4242)));
    assert_eq!(
        (p.cfg.resnet_base, p.cfg.net.down_dims.clone(), p.cfg.net.step_embed),
        (16, vec![16, 32, 64], 16)
    );
    assert_eq!((p.cfg.net.kernel, p.cfg.net.action_dim, p.cfg.net.proprio()), (5, 2, 2));
    let src = io();
    // Conditioning: ResNet features of the frames in [0, 1] and the positions, per frame.
    let cond = cond_of(&p.net, &device);
    let d = max_abs(&cond, &read(&src, "cond"));
    assert!(d <= 1e-5, "conditioning differs from PyTorch by {d}");
    // The noise prediction at steps 3 and 77.
    let x = Tensor::from_data(TensorData::new(read(&src, "x"), [2, 16, 2]), &device);
    let c = Tensor::from_data(TensorData::new(read(&src, "cond"), [2, cond.len() / 2]), &device);
    let eps = p.net.unet.forward(x, Tensor::from_floats([3.0, 77.0], &device), c);
    let eps = eps.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default();
    let d = max_abs(&eps, &read(&src, "eps"));
    assert!(d <= 1e-5, "noise prediction differs from PyTorch by {d}");
}

#[test]
fn the_cpu_kernels_predict_what_pytorch_predicts() {
    // What `act` runs on the CPU: the encoder on `cpu_resnet`, the U-Net on `cpu_unet`, with
    // either kind of products, against the same PyTorch outputs as burn's networks above.
    let device = Device::flex();
    let p = import(&fixture("policy.pth"), GpcWeights::Ema, 96, &device).unwrap_or_else(|e| panic!("{e}"));
    let src = io();
    let (want_cond, x, want_eps) = (read(&src, "cond"), read(&src, "x"), read(&src, "eps"));
    let per = want_cond.len() / 2;
    for products in [Products::GemmCrate, Products::Chain] {
        let enc = CpuResNet18::new(&p.net.encoder, products).unwrap_or_else(|e| panic!("{e}"));
        let d = max_abs(&cond_on(&p.net, &device, Some(&enc)), &want_cond);
        assert!(d <= 1e-5, "{products:?}: conditioning differs from PyTorch by {d}");
        // The fixture's two samples are at steps 3 and 77; the CPU U-Net takes one step a call.
        let unet = CpuUnet1d::new(&p.net.unet, products).unwrap_or_else(|e| panic!("{e}"));
        for (i, t) in [3.0, 77.0].into_iter().enumerate() {
            let prep = unet.prepare(&want_cond[i * per..(i + 1) * per], 1);
            let eps = unet.forward(&prep, &x[i * 32..(i + 1) * 32], 16, t);
            let d = max_abs(&eps, &want_eps[i * 32..(i + 1) * 32]);
            assert!(d <= 1e-5, "{products:?}, step {t}: noise prediction differs from PyTorch by {d}");
        }
    }
}

#[test]
fn ddpm_with_pytorchs_noise_gives_pytorchs_actions() {
    // The fixture's 100-step DDPM run (diffusers' DDPMScheduler as GPC configures it), with
    // its initial and per-step noise handed in: the same normalised action sequence.
    let device = Device::flex();
    let p = import(&fixture("policy.pth"), GpcWeights::Ema, 96, &device).unwrap_or_else(|e| panic!("{e}"));
    let src = io();
    let (cond, x, noises) = (read(&src, "cond"), read(&src, "x"), read(&src, "noises")); // noises [100, 2, 16, 2]
    let ac = crate::diffusion::alphas_cumprod(100);
    let steps: Vec<usize> = (0..100).rev().collect();
    let got = ddpm_sample(x, &ac, &steps, |x, t| unet_out(&p.net, &cond, x, [2, 16, 2], t), replayed(noises));
    let d = max_abs(&got, &read(&src, "actions"));
    assert!(d <= 1e-4, "DDPM differs from PyTorch's by {d}");
}

#[test]
fn the_model_copy_differs_from_the_ema_copy() {
    let device = Device::flex();
    let ema = import(&fixture("policy.pth"), GpcWeights::Ema, 96, &device).unwrap_or_else(|e| panic!("{e}"));
    let raw =
        import(&fixture("policy.pth"), GpcWeights::Model, 96, &device).unwrap_or_else(|e| panic!("{e}"));
    let d = max_abs(&cond_of(&ema.net, &device), &cond_of(&raw.net, &device));
    assert!(d > 1e-4, "the two copies read the same ({d})");
}

#[test]
fn the_official_pusht_manifest_is_the_parameter_order() {
    // The released policies' 208 parameters, names and shapes in `parameters()` order, as the
    // official module lists them (read outside the project); our list and our networks at the
    // full size must match it name for name and place for place.
    let text = std::fs::read_to_string(fixture("pusht_policy_model_keys.tsv")).unwrap_or_default();
    let rows: Vec<(&str, &str)> = text.lines().filter_map(|l| l.split_once('\t')).collect();
    assert_eq!(rows.len(), 208);
    let names = official_names(&[256, 512, 1024], 2);
    assert_eq!(names, rows.iter().map(|r| r.0.to_string()).collect::<Vec<_>>());
    let cfg = ImportedConfig {
        resnet_base: 64,
        backbone_norm: crate::resnet_gn::BackboneNorm::Group,
        pool: crate::imported_policy::Pool::Average,
        input_size: None,
        antialias: false,
        crop: None,
        image_norm: None,
        position_first: false,
        robot_keys: Vec::new(),
        inference_steps: None,
        sampler: crate::imported_policy::Sampler::Ddpm,
        prediction: crate::imported_policy::Prediction::Epsilon,
        net: NetConfig {
            image_size: 96,
            encoder_width: 64,
            feature_dim: 512,
            down_dims: vec![256, 512, 1024],
            kernel: 5,
            step_embed: 256,
            obs_horizon: 2,
            action_dim: 2,
            proprio_dim: Some(2),
        },
        horizon: 16,
        action_horizon: 8,
        train_steps: 100,
    };
    let ours = shapes(&ImportedNet::new(&cfg, &Device::flex()));
    let mut mapped = BTreeSet::new();
    for (name, shape) in &rows {
        let (to, linear) = burn_path(name).unwrap_or_else(|| panic!("no place for {name}"));
        let dims: Vec<usize> = shape
            .trim_matches(|c| c == '(' || c == ')')
            .split(',')
            .filter_map(|d| d.trim().parse().ok())
            .collect();
        let want = if linear { vec![dims[1], dims[0]] } else { dims };
        assert_eq!(ours.get(&to), Some(&want), "{name} -> {to}");
        assert!(mapped.insert(to.clone()), "{to} mapped twice");
    }
    assert_eq!(mapped.len(), ours.len(), "every parameter of ours is mapped");
}

#[test]
fn a_file_that_is_not_a_policy_is_refused_by_key() {
    let device = Device::flex();
    let wm = Path::new(env!("CARGO_MANIFEST_DIR")).join("../world_model/tests/fixtures/driftworld/micro.pth");
    let err = import(&wm, GpcWeights::Ema, 96, &device).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("model.vision_encoder.conv1.weight") || err.contains("model."), "{err}");
    let err = import(&fixture("policy_io.pth"), GpcWeights::Ema, 96, &device)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(err.contains("policy_io.pth") && err.contains("model"), "{err}");
}

#[test]
fn gpcs_folder_layout_imports_to_the_same_networks() {
    // `official/`: the fixture's networks saved as GPC's folder layout (the same seed, so the
    // same values): both weight copies give the file's conditioning, the EMA's PyTorch's.
    let device = Device::flex();
    for w in [GpcWeights::Ema, GpcWeights::Model] {
        let file = import(&fixture("policy.pth"), w, 96, &device).unwrap_or_else(|e| panic!("{e}"));
        let folder = import(&fixture("official"), w, 96, &device).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            (folder.tensors, folder.step),
            (208, Some(4242)),
            "the step is the EMA's optimization_step"
        );
        assert_eq!(cond_of(&folder.net, &device), cond_of(&file.net, &device), "{w:?}");
    }
    // A folder without one of the files is refused naming it.
    let tmp = tempfile::tempdir().unwrap();
    for f in ["vision_encoder.pth", "invariant.pth"] {
        std::fs::copy(fixture("official").join(f), tmp.path().join(f)).unwrap();
    }
    let err =
        import(tmp.path(), GpcWeights::Model, 96, &device).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("ema_nets.pth"), "{err}");
    // A key missing from one part is named with its file.
    std::fs::copy(fixture("official/ema_nets.pth"), tmp.path().join("ema_nets.pth")).unwrap();
    std::fs::copy(fixture("policy_io.pth"), tmp.path().join("invariant.pth")).unwrap();
    let err =
        import(tmp.path(), GpcWeights::Model, 96, &device).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("invariant.pth: *") && err.contains("missing down_modules.0.0"), "{err}");
}
