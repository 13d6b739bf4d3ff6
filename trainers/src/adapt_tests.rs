//! Tests of `train adapt`'s pieces: the autoencoder keeps its decoder, encoders a rounding
//! apart are one.

use super::*;
use policies::data::FrameLabels;
use policies::net::NetConfig;
use world_model::autoencoder::AutoencoderConfig;

/// The tests seed the one Flex device's generator, then draw weights from it: one at a time,
/// or a test running beside another draws weights seeded by neither.
static DEVICE_RNG: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn demos(n: usize, side: usize, shift: u8) -> Demos {
    Demos {
        frames: (0..n * side * side * 3).map(|k| ((k * 13 % 180) as u8).saturating_add(shift)).collect(),
        proprio: vec![0.0; n],
        proprio_dim: 1,
        actions: vec![0.0; n],
        action_dim: 1,
        labels: FrameLabels::None,
        size: side,
        episodes: std::iter::once(0..n).collect(),
    }
}

#[test]
fn distilling_the_autoencoders_encoder_keeps_its_decoder() {
    let device = Device::flex();
    let _rng = DEVICE_RNG.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    device.seed(3);
    let cfg = AutoencoderConfig { image_size: 16, channels: [8, 8, 8, 8], ..AutoencoderConfig::new() };
    let ae = cfg.init(&device);
    let (from, to) = (demos(4, 16, 0), demos(4, 16, 20));
    let steps = [0, 1, 2, 3];
    let pairs = Pairs { from: &from, to: &to, steps: &steps };
    let d = Distil { steps: 2, batch: 2, lr: 1e-2, seed: 0 };
    let student = distil(&ae, ae_encoder, &pairs, d, &device, &mut |_, _| {}).unwrap();
    let z = Tensor::<4>::ones([1, 8, 2, 2], &device);
    let bits = |m: &Autoencoder| {
        m.decode(z.clone()).into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default()
    };
    assert_eq!(bits(&student), bits(&ae), "the decoder is untouched");
    let x = Tensor::<4>::ones([1, 3, 16, 16], &device);
    let enc = |m: &Autoencoder| a_flat(ae_encoder(m, x.clone()));
    assert_ne!(enc(&student), enc(&ae), "the encoder moved");
}

fn a_flat(t: Tensor<2>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default()
}

#[test]
fn encoders_a_rounding_apart_are_one_and_others_are_not() {
    let device = Device::flex();
    let _rng = DEVICE_RNG.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    device.seed(5);
    let cfg = NetConfig { image_size: 16, encoder_width: 8, feature_dim: 8, ..NetConfig::new() };
    let a = ObsEncoder::new(&cfg, &device);
    // The same weights through f16, as checkpoints store them.
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("encoder.bpk");
    policies::dir::save_f16(&a, &path).unwrap();
    let half = policies::dir::load_weights(ObsEncoder::new(&cfg, &device), &path).unwrap();
    assert!(same_encoder(&a, &half, 16, &device));
    let other = ObsEncoder::new(&cfg, &device);
    assert!(!same_encoder(&a, &other, 16, &device));
}
