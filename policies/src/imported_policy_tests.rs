//! DDPM steps by hand, and the policy's determinism per episode.

use super::*;

#[test]
fn the_last_ddpm_step_is_the_clipped_x0_estimate() {
    // t = 0 with ᾱ_0 = 0.9: ᾱ_prev = 1, so the posterior mean is x₀ itself (coefficients 1
    // and 0) and no noise is added: x₀ = (0.5 − √0.1·0.1)/√0.9 = (0.5 − 0.0316228)/0.9486833
    // = 0.4937129; x = 2 with ε = 0 gives 2.108, clipped to 1.
    let mut x = vec![0.5, 2.0];
    ddpm_step(&mut x, &[0.1, 0.0], 0, None, &[0.9], &[]);
    assert!((x[0] - 0.493_712_9).abs() < 1e-6 && x[1] == 1.0, "{x:?}");
}

#[test]
fn an_inner_ddpm_step_adds_the_posterior_noise() {
    // t = 1 of ᾱ = [0.9, 0.8]: ᾱ_t = 0.8, ᾱ_prev = 0.9, α_t = 0.8/0.9 = 0.888889, β_t = 0.111111.
    // x = 0, ε = 0: x₀ = 0, mean 0; variance (1 − 0.9)/(1 − 0.8)·0.111111 = 0.0555556, so
    // z = 1 adds √0.0555556 = 0.2357023.
    let mut x = vec![0.0];
    ddpm_step(&mut x, &[0.0], 1, Some(0), &[0.9, 0.8], &[1.0]);
    assert!((x[0] - 0.235_702_3).abs() < 1e-6, "{x:?}");
}

#[test]
fn sampling_draws_noise_for_every_step_but_the_last() {
    let ac = crate::diffusion::alphas_cumprod(10);
    let mut draws = 0;
    let steps: Vec<usize> = (0..10).rev().collect();
    let out = ddpm_sample(
        vec![0.3; 4],
        &ac,
        &steps,
        |x: &[f32], _| vec![0.0; x.len()],
        |n| {
            draws += 1;
            vec![0.0; n]
        },
    );
    assert_eq!(draws, 9);
    assert!(out.iter().all(|v| v.is_finite() && v.abs() <= 1.0), "{out:?}");
}

#[test]
fn leading_spacing_steps_from_the_last_multiple_down_to_zero() {
    // 100 training steps sampled in 10: t = j · ⌊100 / 10⌋, j = 9 … 0 (diffusers' "leading").
    let cfg = |n: Option<usize>| ImportedConfig {
        resnet_base: 16,
        backbone_norm: crate::resnet_gn::BackboneNorm::Group,
        pool: Pool::Average,
        input_size: None,
        antialias: false,
        crop: None,
        image_norm: None,
        position_first: false,
        robot_keys: Vec::new(),
        inference_steps: n,
        sampler: Sampler::Ddpm,
        prediction: crate::imported_policy::Prediction::Epsilon,
        net: crate::net::NetConfig::new(),
        horizon: 16,
        action_horizon: 8,
        train_steps: 100,
    };
    assert_eq!(cfg(Some(10)).timesteps(), [90, 80, 70, 60, 50, 40, 30, 20, 10, 0]);
    assert_eq!(cfg(None).timesteps().len(), 100);
    assert_eq!(cfg(None).timesteps()[..3], [99, 98, 97]);
}

#[test]
fn unrounded_frames_are_read_when_the_observation_has_them() {
    // The GPC fixture policy: an observation whose exact values are its bytes / 255 acts as
    // the bytes alone do (same noise streams); shifted exact values change the actions, so the
    // floats, not the bytes, were read.
    use harness::policy::{Observation, Policy};
    use harness::rng::Rng;
    let device = Device::flex();
    let fixture =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/gpc_policy/policy.pth");
    let p = crate::import_gpc::import(&fixture, crate::import_gpc::GpcWeights::Ema, 96, &device)
        .unwrap_or_else(|e| panic!("{e}"));
    let norm = crate::diffusion::Normalisation {
        agent_pos: crate::diffusion::Range { min: vec![0.0; 2], max: vec![512.0; 2] },
        action: crate::diffusion::Range { min: vec![0.0; 2], max: vec![512.0; 2] },
    };
    let policy =
        ImportedDiffusion::new("p".into(), p.cfg, norm, (vec![0.0; 2], vec![512.0; 2]), p.net, &device);
    let frame: Vec<u8> = (0..96 * 96 * 3).map(|i| (i * 7 % 251) as u8).collect();
    let bytes = Observation {
        frames: vec![frame.clone(); 2],
        proprio: vec![vec![100.0, 200.0]; 2],
        robot: vec![Vec::new(); 2],
        size: 96,
        exact: None,
        native: None,
    };
    let unit: Vec<f32> = frame.iter().map(|&b| f32::from(b) / 255.0).collect();
    let same = Observation { exact: Some(vec![unit.clone(); 2]), ..bytes.clone() };
    let shifted: Vec<f32> = unit.iter().map(|v| v + 0.05).collect();
    let other = Observation { exact: Some(vec![shifted; 2]), ..bytes.clone() };
    let act = |o: &Observation| {
        policy.act(std::slice::from_ref(o), &mut [Rng::new(9)]).unwrap_or_else(|e| panic!("{e}"))
    };
    let (a, b, c) = (act(&bytes), act(&same), act(&other));
    let d = |x: &[Vec<f32>], y: &[Vec<f32>]| {
        x.iter().flatten().zip(y.iter().flatten()).map(|(u, v)| (u - v).abs()).fold(0.0f32, f32::max)
    };
    assert!(d(&a[0], &b[0]) < 1e-3, "bytes and their exact values act alike");
    assert!(d(&a[0], &c[0]) > 1e-3, "shifted exact values were not read");
}

#[test]
fn centre_crops_start_where_torchvision_starts_them() {
    // round(m / 2), halves to even: 8 → 4, 3 → round(1.5) = 2, 5 → round(2.5) = 2, 7 → 4.
    let got: Vec<usize> =
        [0, 1, 3, 5, 7, 8, 12].iter().map(|&m| crate::imported_policy::centre_offset(m)).collect();
    assert_eq!(got, [0, 0, 2, 2, 4, 4, 6]);
}
