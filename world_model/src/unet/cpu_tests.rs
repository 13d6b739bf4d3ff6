//! The CPU U-Net ([`super::cpu::CpuUNet`]) against burn's ([`UNet::forward`]).

use burn::module::Module;
use burn::tensor::{Device, Distribution, Tensor};

use super::cpu::CpuUNet;
use super::{UNet, UNetConfig};
use nn::weights::Jitter;

fn vec_of<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().unwrap_or_default()
}

/// Runs both on the same random inputs and returns the largest difference relative
/// to the output's scale.
fn compare(unet: &UNet, cf: usize, side: usize, timestep: bool) -> f32 {
    let device = Device::flex();
    let cpu = CpuUNet::new(unet).unwrap_or_else(|e| panic!("{e}"));
    let (b, f, k) = (3, 4, 4);
    let rand = |s: [usize; 5]| Tensor::<5>::random(s, Distribution::Normal(0.0, 1.0), &device);
    let noise = rand([b, cf, f, side, side]);
    let history = rand([b, cf, k, side, side]);
    let actions = Tensor::<3>::random([b, f, 2], Distribution::Uniform(-1.0, 1.0), &device);
    let anchor = Some(Tensor::<4>::random([b, cf, side, side], Distribution::Normal(0.0, 1.0), &device));
    let t = timestep.then(|| Tensor::<1>::from_floats([0.9f32, 0.5, 0.1].as_slice(), &device));
    // α = 2.5 for all (read only by accentuated U-Nets).
    let alpha = Some(Tensor::<1>::full([b], 2.5, &device));
    let want = vec_of(unet.forward_accentuated(
        noise.clone(),
        history.clone(),
        actions.clone(),
        anchor.clone(),
        t.clone(),
        alpha.clone(),
    ));
    let x = unet.inputs(noise, history, actions.clone(), anchor);
    let dims = x.dims();
    let got = cpu.forward(&vec_of(x), &vec_of(unet.embedding(actions, t, alpha)), dims);
    assert_eq!(got.len(), want.len());
    assert!(got.iter().all(|v| v.is_finite()));
    let scale = want.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
    assert!(scale > 1e-2, "degenerate test output");
    got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max) / scale.max(1.0)
}

#[test]
fn predicts_what_burn_predicts_with_action_maps_anchor_and_accentuation() {
    // The shipped model's layout at a smaller width: two levels (a stride-2 convolution,
    // an upsampling), attention at the coarse level and in the middle, skip
    // convolutions where channel counts change, the anchor and action-map inputs, and
    // the accentuation strength's MLP.
    let device = Device::flex();
    let cfg = UNetConfig {
        model_channels: 32,
        action_maps: Some(true),
        anchor: Some(true),
        ..UNetConfig::pusht_latent(4)
    };
    let unet = cfg.init(&device).map(&mut Jitter);
    let diff = compare(&unet, 4, 8, false);
    assert!(diff < 1e-4, "max relative difference {diff}");
}

#[test]
fn predicts_what_burn_predicts_with_a_timestep_and_three_levels() {
    // The diffusion baseline's timestep MLP; three levels with attention at rate 2 only.
    let device = Device::flex();
    let cfg = UNetConfig {
        model_channels: 16,
        timestep_embedding: true,
        channel_mult: vec![1, 2, 2],
        groups: 8,
        ..UNetConfig::pusht_latent(3)
    };
    let unet = cfg.init(&device).map(&mut Jitter);
    let diff = compare(&unet, 3, 8, true);
    assert!(diff < 1e-4, "max relative difference {diff}");
}

#[test]
fn predicts_what_burn_predicts_with_per_frame_attention_norm() {
    // The official DriftWorld layout (imported models): attention GroupNorm per frame,
    // 3-channel frames, every level at the base width, attention at rates 2 and 4.
    let device = Device::flex();
    let cfg = UNetConfig {
        frame_attention_norm: Some(true),
        groups: 8,
        ..UNetConfig::new(3, 16, vec![1, 1, 1], vec![2, 4])
    };
    let unet = cfg.init(&device).map(&mut Jitter);
    let diff = compare(&unet, 3, 8, false);
    assert!(diff < 1e-4, "max relative difference {diff}");
}
