//! The robomimic import against PyTorch: fixtures written by `scripts/fixtures/robomimic_policy.py`
//! (evalharness's own re-implementation of a robomimic 0.5 diffusion-policy checkpoint, checked
//! outside the project against robomimic's own `DiffusionPolicyUNet` at the full size: the same
//! 280 names and shapes, identical features and noise; reduced here to ResNet base 16, 4
//! keypoints, 6 features, U-Net levels 16/32/64, 84² images cropped to 76).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor, TensorData};
use harness::policy::{Observation, Policy};
use harness::rng::Rng;
use harness::task::NativeFrame;

use super::*;
use crate::imported_policy::{ImportedDiffusion, bilinear_weights, ddpm_sample, replayed, unet_out};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/robomimic_policy").join(name)
}

fn io(k: &str) -> Vec<f32> {
    let src = Source::open(&fixture("policy_io.pth"), None, "").unwrap_or_else(|e| panic!("{e}"));
    let s = src.shapes()[k].clone();
    src.f32s(k, &s).unwrap_or_else(|e| panic!("{e}"))
}

fn frames() -> Vec<u8> {
    let r = pytorch_reader::PytorchReader::new(fixture("policy_io.pth")).unwrap_or_else(|e| panic!("{e}"));
    r.get("frames").and_then(|t| t.read().ok()).unwrap_or_default() // [2, 2, 96, 96, 3]
}

fn max_abs(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

fn imported(weights: RobomimicWeights) -> RobomimicPolicy {
    import(&fixture("policy.pth"), weights, 96, &Device::flex()).unwrap_or_else(|e| panic!("{e}"))
}

fn err_of(name: &str, weights: RobomimicWeights) -> String {
    import(&fixture(name), weights, 96, &Device::flex()).err().map(|e| e.to_string()).unwrap_or_default()
}

/// The imported networks' conditioning of the fixture's frames and (raw) robot states.
fn cond_of(p: &RobomimicPolicy) -> Vec<f32> {
    let device = Device::flex();
    let bytes = frames();
    let f: Vec<&[u8]> = bytes.chunks(96 * 96 * 3).collect();
    let x01 = nn::frames::frames_to_tensor(&f, 96, &device) * 0.5 + 0.5;
    let pos: Vec<f32> =
        io("robot").chunks(9).flat_map(|s| p.norm.agent_pos.normalise(s).collect::<Vec<_>>()).collect();
    let pos = Tensor::from_data(TensorData::new(pos, [2, 2, 9]), &device);
    p.net.obs_cond(x01, pos).into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default()
}

/// The imported networks as a Lift policy whose robot-state keys lie at `robot` (offset, width).
fn as_policy(p: RobomimicPolicy, robot: Vec<(usize, usize)>) -> ImportedDiffusion {
    let mut policy = ImportedDiffusion::new(
        "rm".into(),
        p.cfg,
        p.norm,
        (vec![-1.0; 7], vec![1.0; 7]),
        p.net,
        &Device::flex(),
    );
    policy.robot = robot;
    policy
}

#[test]
fn the_ema_copy_imports_with_robomimics_settings() {
    let p = imported(RobomimicWeights::Ema);
    // 280 state-dict entries: 62 backbone + 4 pool (conv weight, bias, temperature, grid
    // ×2) counted twice, 2 Linear, and the U-Net; placed: 62 + 2 + 2 + the U-Net's.
    assert_eq!(p.weights, "model.ema");
    assert_eq!((p.epoch, p.env_name.as_deref()), (Some(120), Some("Lift")));
    assert_eq!(p.cfg.pool, Pool::SpatialSoftmax { keypoints: 4, features: Some(6) });
    assert_eq!((p.cfg.input_size, p.cfg.crop, p.cfg.position_first), (Some(84), Some(76), false));
    assert_eq!(p.cfg.robot_keys, ["robot0_eef_pos", "robot0_eef_quat", "robot0_gripper_qpos"]);
    assert_eq!((p.cfg.net.proprio(), p.cfg.net.action_dim, p.cfg.net.feature_dim), (9, 7, 6));
    assert_eq!(
        (p.cfg.horizon, p.cfg.action_horizon, p.cfg.train_steps, p.cfg.inference_steps),
        (16, 8, 100, None)
    );
    // No observation statistics: the state is read raw (the identity range).
    assert_eq!((p.norm.agent_pos.min.clone(), p.norm.agent_pos.max.clone()), (vec![-1.0; 9], vec![1.0; 9]));
    // Actions: scale 0.9, offset 0.05 → [−0.85, 0.95] for the first entry.
    assert!((p.norm.action.min[0] + 0.85).abs() < 1e-6 && (p.norm.action.max[0] - 0.95).abs() < 1e-6);
}

#[test]
fn features_conditioning_and_noise_match_pytorch() {
    let p = imported(RobomimicWeights::Ema);
    // Resized 96 → 84, cropped to 76, VisualCore with the temperature folded in, ReLU; then the
    // robot state, frame by frame.
    let cond = cond_of(&p);
    let want = io("cond");
    let d = max_abs(&cond, &want);
    assert!(d <= 1e-5, "conditioning differs from PyTorch by {d}");
    let device = Device::flex();
    let x = Tensor::from_data(TensorData::new(io("x"), [2, 16, 7]), &device);
    let c = Tensor::from_data(TensorData::new(want, [2, 30]), &device);
    let eps = p.net.unet.forward(x, Tensor::from_floats([3.0, 77.0], &device), c);
    let d = max_abs(&eps.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default(), &io("eps"));
    assert!(d <= 1e-5, "noise prediction differs from PyTorch by {d}");
}

#[test]
fn ddpm_with_pytorchs_noise_gives_pytorchs_actions() {
    let p = imported(RobomimicWeights::Ema);
    let cond = io("cond");
    // PyTorch's initial and per-step noise (`noises` [100, 2, 16, 7]) handed in.
    let got = ddpm_sample(
        io("x"),
        &crate::diffusion::alphas_cumprod(100),
        &p.cfg.timesteps(),
        |x, t| unet_out(&p.net, &cond, x, [2, 16, 7], t),
        replayed(io("noises")),
    );
    let d = max_abs(&got, &io("actions"));
    assert!(d <= 1e-4, "DDPM differs from PyTorch's by {d}");
}

#[test]
fn one_ddpm_step_with_injected_noise_is_pytorchs() {
    // From x at t = 77 to 76, given PyTorch's noise prediction there and its noise z: the step's
    // arithmetic alone (x0 clipped, the posterior mean, "fixed_small" variance).
    let (mut x, eps, z) = (io("x"), io("eps77"), io("z"));
    crate::imported_policy::ddpm_step(&mut x, &eps, 77, Some(76), &crate::diffusion::alphas_cumprod(100), &z);
    let d = max_abs(&x, &io("step77"));
    assert!(d <= 1e-6, "one DDPM step differs from PyTorch's by {d}");
    // The networks' own prediction there is PyTorch's within 1e-5.
    let p = imported(RobomimicWeights::Ema);
    let ours = unet_out(&p.net, &io("cond"), &io("x"), [2, 16, 7], 77);
    assert!(max_abs(&ours, &eps) <= 1e-5);
}

#[test]
fn the_policy_reads_its_keys_from_the_robot_state_and_the_training_copy_differs() {
    let p = imported(RobomimicWeights::Ema);
    let raw = imported(RobomimicWeights::Model);
    assert_eq!(raw.weights, "model.nets");
    assert!(max_abs(&cond_of(&p), &cond_of(&raw)) > 1e-4, "the two copies read the same");
    // As a policy: the task's robot state laid out with an extra key first, which it skips.
    let policy = as_policy(p, vec![(2, 3), (5, 4), (9, 2)]);
    let bytes = frames();
    let ob = |e: usize, extra: f32| Observation {
        frames: (0..2)
            .map(|i| bytes[(2 * e + i) * 96 * 96 * 3..(2 * e + i + 1) * 96 * 96 * 3].to_vec())
            .collect(),
        proprio: vec![vec![0.0; 7]; 2],
        robot: io("robot")[e * 18..(e + 1) * 18]
            .chunks(9)
            .map(|r| [extra, extra].iter().chain(r).copied().collect())
            .collect(),
        size: 96,
        exact: None,
        native: None,
    };
    let act = |extra| policy.act(&[ob(0, extra)], &mut [Rng::new(3)]).unwrap_or_else(|e| panic!("{e}"));
    let a = act(0.0);
    assert_eq!((a.len(), a[0].len(), a[0][0].len()), (1, 8, 7));
    assert_eq!(a, act(5.0), "entries the policy does not read change nothing");
    let short = Observation { robot: vec![vec![0.0; 4]; 2], ..ob(0, 0.0) };
    let err = policy.act(&[short], &mut [Rng::new(3)]).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("robot0_eef_pos"), "{err}");
}

#[test]
fn the_cameras_own_frames_at_the_policys_size_are_read_instead_of_resized_ones() {
    // A scene rendering at 84 and upsampling (`[visual] render_size = 84`) hands the camera's
    // own 84² frames beside the 96² ones; the policy (trained at 84) reads those, not a resize.
    let policy = as_policy(imported(RobomimicWeights::Ema), vec![(0, 3), (3, 4), (7, 2)]);
    let bytes = frames();
    let f96: Vec<Vec<u8>> = bytes.chunks(96 * 96 * 3).take(2).map(<[u8]>::to_vec).collect();
    let ob = |frames: Vec<Vec<u8>>, native: Option<Vec<NativeFrame>>| Observation {
        frames,
        proprio: vec![vec![0.0; 7]; 2],
        robot: io("robot")[..18].chunks(9).map(<[f32]>::to_vec).collect(),
        size: 96,
        exact: None,
        native,
    };
    // Native frames unlike the 96² ones (the fixture's second episode, at `side`).
    let other = |side: usize| -> Vec<NativeFrame> {
        bytes
            .chunks(96 * 96 * 3)
            .skip(2)
            .map(|f| NativeFrame {
                side,
                bytes: harness::resize::resize_bilinear_torch_u8(f, 96, 96, 3, side, side)
                    .unwrap_or_default(),
            })
            .collect()
    };
    let act = |o: Observation| policy.act(&[o], &mut [Rng::new(3)]).unwrap_or_else(|e| panic!("{e}"));
    let resized = act(ob(f96.clone(), None));
    let native = act(ob(f96.clone(), Some(other(84))));
    assert_ne!(resized, native, "the camera's own frames are read");
    // With them the 96² frames are not read at all.
    assert_eq!(act(ob(vec![vec![128; 96 * 96 * 3]; 2], Some(other(84)))), native);
    // Frames of another side than the policy's are not what it was trained on: resized as before.
    assert_eq!(act(ob(f96, Some(other(80)))), resized);
}

#[test]
fn the_expected_names_are_the_fixtures_keys() {
    // Every name robomimic's layout gives these sizes is in the fixture, and the fixture holds
    // nothing else but the copies, the temperature and the grid.
    let src = Source::open(&fixture("policy.pth"), Some("model"), "ema.").unwrap_or_else(|e| panic!("{e}"));
    let enc = format!("{ENCODER}{IMAGE_KEY}.");
    let names = expected_names(&enc, &[16, 32, 64], 7);
    let have = src.shapes();
    assert!(
        names.iter().all(|n| have.contains_key(n)),
        "{:?}",
        names.iter().find(|n| !have.contains_key(*n))
    );
    let extra: Vec<&String> = have.keys().filter(|k| !names.contains(k)).collect();
    assert!(
        extra.iter().all(|k| k.contains(".nets.0.")
            || k.contains(".nets.1.")
            || k.contains("pool.temperature")
            || k.contains("pool.pos_")),
        "{extra:?}"
    );
    assert_eq!(names.len() + extra.len(), have.len());
}

#[test]
fn bilinear_weights_are_pytorchs() {
    // 96 → 84: scale 8/7; output 0 samples 8/7 · 0.5 − 0.5 = 0.0714 → taps 0 and 1 with weights
    // 0.9286 and 0.0714; output 83 samples 8/7 · 83.5 − 0.5 = 94.93 → taps 94, 95.
    let w = bilinear_weights(96, 84, false);
    assert!((w[0] - 0.928_571_4).abs() < 1e-6 && (w[1] - 0.071_428_6).abs() < 1e-6);
    assert!((w[83 * 96 + 94] - 0.071_428_6).abs() < 1e-5 && (w[83 * 96 + 95] - 0.928_571_4).abs() < 1e-5);
    assert!(w.chunks(96).all(|r| (r.iter().sum::<f32>() - 1.0).abs() < 1e-6));
}

#[test]
fn broken_files_are_refused_naming_the_key_or_field() {
    let e = err_of("broken.pth", RobomimicWeights::Model);
    assert!(e.contains("`model.nets.policy.noise_pred_net.final_conv.1.bias` is missing"), "{e}");
    let e = err_of("broken.pth", RobomimicWeights::Ema);
    assert!(e.contains("nets.0.nets.0.weight") && e.contains("is not a copy of"), "{e}");
    let e = err_of("eye_in_hand.pth", RobomimicWeights::Ema);
    assert!(e.contains("robot0_eye_in_hand_image") && e.contains("imagines"), "{e}");
    let e = err_of("wrong_shape.pth", RobomimicWeights::Model);
    assert!(e.contains("backbone.nets.0.weight") && e.contains("[16, 3, 5, 5]"), "{e}");
    let e = err_of("wrong_shape.pth", RobomimicWeights::Ema);
    assert!(e.contains("model.ema"), "EMA enabled but not stored: {e}");
    let e = err_of("policy_io.pth", RobomimicWeights::Ema);
    assert!(e.contains("algo_name"), "{e}");
    // A 77 crop of 84: robomimic starts it at ⌊7 / 2⌋ = 3, torchvision at round-half-even(3.5) = 4.
    let e = err_of("odd_crop.pth", RobomimicWeights::Ema);
    assert!(e.contains("crop 77 of 84x84") && e.contains("torchvision"), "{e}");
    let d = declared(&fixture("object_key.pth")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        (d.low_dim, d.env_name.as_deref()),
        (vec!["object".to_string(), "robot0_eef_pos".into()], Some("Lift"))
    );
}

#[test]
fn robomimics_full_size_manifest_maps_every_weight_exactly_once() {
    // robomimic_dp_full_keys.tsv: the state dict of robomimic's own DiffusionPolicyUNet at its
    // default size (written by the cross-check outside the project). Every weight but the
    // copies (`nets.0.*`, `nets.1.*`), the temperature and the grid lands on one parameter of
    // the full-size networks with its shape, and every parameter is reached.
    let text = std::fs::read_to_string(fixture("robomimic_dp_full_keys.tsv")).unwrap();
    let entries: Vec<(String, Vec<usize>)> = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let (k, s) = l.split_once('\t').unwrap();
            let dims = s
                .trim_matches(['[', ']'])
                .split(", ")
                .filter(|d| !d.is_empty())
                .map(|d| d.parse().unwrap())
                .collect();
            (k.to_string(), dims)
        })
        .collect();
    assert_eq!(entries.len(), 280);
    let full = NetConfig {
        image_size: 96,
        encoder_width: 64,
        feature_dim: 64,
        down_dims: vec![256, 512, 1024],
        kernel: 5,
        step_embed: 256,
        obs_horizon: 2,
        action_dim: 7,
        proprio_dim: Some(9),
    };
    let pool = Pool::SpatialSoftmax { keypoints: 32, features: Some(64) };
    let cfg = ImportedConfig { net: full, resnet_base: 64, pool, ..imported(RobomimicWeights::Ema).cfg };
    let ours = shapes(&ImportedNet::new(&cfg, &Device::flex()));
    let enc = format!("{ENCODER}{IMAGE_KEY}.");
    let skipped = |k: &str| {
        let local = k.strip_prefix(enc.as_str()).unwrap_or("");
        local.starts_with("nets.0.")
            || local.starts_with("nets.1.")
            || ["pool.temperature", "pool.pos_x", "pool.pos_y"].contains(&local)
    };
    let mut mapped = BTreeSet::new();
    for (k, theirs) in entries.iter().filter(|(k, _)| !skipped(k)) {
        let (to, linear) = burn_path(&enc, k).unwrap_or_else(|| panic!("{k} has no place"));
        let want = if linear { vec![theirs[1], theirs[0]] } else { theirs.clone() };
        assert_eq!(ours.get(&to), Some(&want), "{k} -> {to}");
        assert!(mapped.insert(to.clone()), "{to} mapped twice");
    }
    assert_eq!(mapped.len(), ours.len(), "every parameter is reached");
    // The names the importer requires at these sizes are exactly the manifest's originals.
    let names: BTreeSet<String> = expected_names(&enc, &[256, 512, 1024], 7).into_iter().collect();
    let originals: BTreeSet<String> =
        entries.iter().map(|(k, _)| k.clone()).filter(|k| !skipped(k)).collect();
    assert_eq!(names, originals);
}
