//! Tests of the CPU U-Net ([`super`]): mish, and the whole network against burn's on both
//! kinds of products.

use burn::module::Module;
use burn::tensor::{Device, Distribution, Tensor};
use nn::weights::Jitter;

use super::*;
use crate::net::NetConfig;

#[test]
fn mish_matches_its_definition() {
    for x in [-30.0f32, -5.0, -1.0, -0.1, 0.0, 0.3, 1.0, 4.0, 19.9, 25.0] {
        let softplus = if x > 20.0 { x } else { x.exp().ln_1p() };
        let want = x * softplus.tanh();
        assert!((mish(x) - want).abs() <= 1e-6 * want.abs().max(1.0), "mish({x}) = {} vs {want}", mish(x));
    }
}

#[test]
fn predicts_what_burn_predicts() {
    // The shipped policies' sizes: 3 levels (down and up resampling both exercised),
    // kernel 5, skip convolutions where the channel count changes.
    let device = Device::flex();
    let cfg = NetConfig { down_dims: vec![32, 64, 128], ..NetConfig::new() };
    let unet = CondUnet1d::new(&cfg, &device).map(&mut Jitter);
    let cpus = [Products::GemmCrate, Products::Chain]
        .map(|p| CpuUnet1d::new(&unet, p).unwrap_or_else(|e| panic!("{e}")));
    let (n, h) = (3, 16);
    let x = Tensor::<3>::random([n, h, 2], Distribution::Normal(0.0, 1.0), &device);
    let obs = Tensor::<2>::random([n, cfg.obs_cond_dim()], Distribution::Normal(0.0, 1.0), &device);
    for t in [0.0f32, 37.0, 99.0] {
        let want: Vec<f32> = unet
            .forward(x.clone(), Tensor::from_floats(vec![t; n].as_slice(), &device), obs.clone())
            .into_data()
            .try_to_vec()
            .unwrap_or_default();
        let xs: Vec<f32> = x.clone().into_data().try_to_vec().unwrap_or_default();
        let os: Vec<f32> = obs.clone().into_data().try_to_vec().unwrap_or_default();
        for cpu in &cpus {
            let got = cpu.forward(&cpu.prepare(&os, n), &xs, h, t);
            assert_eq!(got.len(), n * h * 2);
            let scale = want.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
            let max = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
            assert!(scale > 1e-2, "degenerate test output");
            assert!(
                max < 1e-4 * scale.max(1.0),
                "{:?}, t = {t}: max difference {max} (output scale {scale})",
                cpu.products
            );
        }
    }
}
