//! Tests of inference sampling: the DDIM sampler against the one-pass model, the
//! cosine schedule, the sampling temperature (`noise_scale`) and the α in effect.

use super::*;

#[test]
fn one_ddim_step_of_an_x0_model_is_its_one_pass_prediction() {
    // K = 1 goes from t = 1 to 0 and ᾱ(0) = 1, so x ← √1·x0 + √0·ε: the U-Net's x0
    // output. With a zero-output timestep embedding that is exactly what the
    // one-pass model it was warm-started from predicts from the same noise.
    let device = Device::flex();
    let unet_cfg = UNetConfig { model_channels: 32, ..UNetConfig::pusht_latent(3) };
    let one_pass = WorldModelConfig::pixels(unet_cfg.clone(), 8);
    let diffusion = WorldModelConfig {
        objective: Objective::Diffusion,
        unet: UNetConfig { timestep_embedding: true, ..unet_cfg.clone() },
        prediction: Some(Prediction::X0),
        ..one_pass.clone()
    };
    let unet = unet_cfg.init(&device);
    let timed = unet.clone().with_timestep_embedding(&device);
    let a = WorldModel::from_parts(one_pass, FrameCodec::pixels(8), unet, &device);
    let mut b = WorldModel::from_parts(diffusion, FrameCodec::pixels(8), timed, &device);
    let hist = Tensor::<5>::random([2, 4, 3, 8, 8], burn::tensor::Distribution::Default, &device);
    let act = Tensor::<3>::zeros([2, 4, 2], &device);
    let rngs = || (0..2).map(Rng::new).collect::<Vec<_>>();
    let anchor = hist.clone().narrow(1, 0, 1).reshape([2, 3, 8, 8]);
    let ya = a.predict(hist.clone(), anchor.clone(), act.clone(), &mut rngs());
    let yb = b.predict(hist.clone(), anchor.clone(), act.clone(), &mut rngs());
    let diff: f32 = (ya.clone() - yb).abs().max().into_scalar();
    assert!(diff < 1e-5, "one x0 DDIM step differs from the one-pass output by {diff}");
    // More steps re-noise and denoise again: a different, finite sample.
    b.cfg.sample_steps = 4;
    let y4 = b.predict(hist, anchor, act, &mut rngs());
    let moved: f32 = (ya - y4.clone()).abs().mean().into_scalar();
    assert!(moved > 1e-4, "{moved}");
    assert!(y4.into_data().try_to_vec::<f32>().unwrap().iter().all(|v| v.is_finite()));
}

#[test]
fn cosine_schedule_ends() {
    // ᾱ(0) = 1 exactly; ᾱ(1) = cos²(π/2) / cos²(0.008/1.008 · π/2) ≈ 0, clamped to 1e-5.
    assert_eq!(alpha_bar(0.0), 1.0);
    assert_eq!(alpha_bar(1.0), 1e-5);
    // ᾱ(0.5) = cos²(0.508/1.008 · π/2) / cos²(0.008/1.008 · π/2) = 0.49384 (hand-computed).
    assert!((alpha_bar(0.5) - 0.49384).abs() < 1e-4, "{}", alpha_bar(0.5));
}

/// A small untrained one-pass model on 3 × 8 × 8 pixel frames, and its inputs for 2 rows.
fn one_pass() -> (WorldModel, Tensor<5>, Tensor<4>, Tensor<3>) {
    let device = Device::flex();
    let unet_cfg = UNetConfig { model_channels: 32, ..UNetConfig::pusht_latent(3) };
    let cfg = WorldModelConfig::pixels(unet_cfg.clone(), 8);
    let wm = WorldModel::from_parts(cfg, FrameCodec::pixels(8), unet_cfg.init(&device), &device);
    let hist = Tensor::<5>::random([2, 4, 3, 8, 8], burn::tensor::Distribution::Default, &device);
    let anchor = hist.clone().narrow(1, 0, 1).reshape([2, 3, 8, 8]);
    let act = Tensor::<3>::zeros([2, 4, 2], &device);
    (wm, hist, anchor, act)
}

fn max_diff(a: Tensor<5>, b: Tensor<5>) -> f32 {
    (a - b).abs().max().into_scalar()
}

#[test]
fn noise_scale_zero_predicts_one_chunk_whatever_the_rng() {
    let (mut wm, hist, anchor, act) = one_pass();
    let rngs = |seed: u64| (seed..seed + 2).map(Rng::new).collect::<Vec<_>>();
    let predict =
        |wm: &WorldModel, seed| wm.predict(hist.clone(), anchor.clone(), act.clone(), &mut rngs(seed));
    // At the trained temperature, other noise gives another chunk.
    let (a, b) = (predict(&wm, 0), predict(&wm, 10));
    assert!(max_diff(a.clone(), b) > 1e-4);
    // Scale 1, written out, is the default: the same chunk from the same noise.
    wm.set_noise_scale(1.0).unwrap();
    assert_eq!(max_diff(predict(&wm, 0), a.clone()), 0.0);
    // Scale 0: the U-Net reads zeros, so every RNG gives the same chunk, and a
    // different one from the sampled chunk.
    wm.set_noise_scale(0.0).unwrap();
    let zero = predict(&wm, 0);
    assert_eq!(max_diff(predict(&wm, 10), zero.clone()), 0.0);
    assert!(max_diff(zero.clone(), a) > 1e-4);
    // It is the U-Net's output for zero noise, read directly.
    let hist_c = hist.clone().swap_dims(1, 2); // [b, C, K, s, s]
    let direct =
        wm.unet_forward(Tensor::<5>::zeros([2, 3, 4, 8, 8], wm.device()), hist_c, act.clone(), None, None);
    assert_eq!(max_diff(direct.swap_dims(1, 2), zero), 0.0);
    // The row RNGs advance as at any scale, so the draws after a chunk do not depend on it.
    let mut r = rngs(0);
    wm.predict(hist.clone(), anchor.clone(), act.clone(), &mut r);
    let mut s = rngs(0);
    wm.set_noise_scale(1.0).unwrap();
    wm.predict(hist, anchor, act, &mut s);
    assert_eq!(r[1].normals_f32(3), s[1].normals_f32(3));
}

#[test]
fn a_noise_scale_outside_zero_to_one_or_on_a_diffusion_model_is_refused() {
    let (mut wm, ..) = one_pass();
    for bad in [-0.1, 1.5, f32::NAN, f32::INFINITY] {
        let err = wm.set_noise_scale(bad).unwrap_err().to_string();
        assert!(err.contains("must be a finite value in [0, 1]"), "{err}");
    }
    assert_eq!(wm.cfg.noise_scale, None, "a refused scale leaves the model as it was");
    wm.cfg.objective = Objective::Diffusion;
    assert_eq!(wm.set_noise_scale(0.5), Err(crate::error::SettingError::NoTemperature));
}

#[test]
fn the_noise_scale_is_written_only_when_set() {
    let (wm, ..) = one_pass();
    let plain = serde_json::to_value(&wm.cfg).unwrap();
    assert!(plain.get("noise_scale").is_none(), "{plain}");
    let cfg = WorldModelConfig { noise_scale: Some(0.5), ..wm.cfg.clone() };
    let v = serde_json::to_value(&cfg).unwrap();
    assert_eq!(v["noise_scale"], 0.5);
    let back: WorldModelConfig = serde_json::from_value(v).unwrap();
    assert_eq!(back, cfg);
}

#[test]
fn alpha_is_the_one_in_effect_and_none_without_accentuation() {
    // A plain model has no α input: `set_alpha` is refused and `alpha()` is None.
    let (mut plain, ..) = one_pass();
    assert_eq!(plain.alpha(), None);
    assert!(plain.set_alpha(2.0).is_err());
    assert_eq!(plain.alpha(), None);
    // An accentuated model whose config sets no α runs at α = 1 (the U-Net's
    // `None` means 1), so that is the value in effect; a set α replaces it.
    let device = Device::flex();
    let unet_cfg = UNetConfig { model_channels: 32, accentuation: Some(true), ..UNetConfig::pusht_latent(3) };
    let cfg = WorldModelConfig::pixels(unet_cfg.clone(), 8);
    assert_eq!(cfg.alpha, None);
    let mut acc = WorldModel::from_parts(cfg, FrameCodec::pixels(8), unet_cfg.init(&device), &device);
    assert_eq!(acc.alpha(), Some(1.0));
    acc.set_alpha(4.0).unwrap();
    assert_eq!(acc.alpha(), Some(4.0));
}
