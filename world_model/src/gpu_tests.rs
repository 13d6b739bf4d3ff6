//! The world model on burn's wgpu backend against Flex (built with `--features wgpu` only).

use burn::tensor::Device;

use nn::device::parse;

/// Built with `--features wgpu` only, and run where a Vulkan driver is
/// (lavapipe on a CPU: `apt-get install mesa-vulkan-drivers`): the same U-Net
/// weights and inputs give the same chunk on wgpu as on Flex, up to f32
/// rounding in a different order of operations.
#[cfg(feature = "wgpu")]
#[test]
fn wgpu_predicts_what_flex_predicts() {
    use crate::unet::UNetConfig;
    use burn::module::Module;
    use burn::tensor::{Distribution, Tensor};
    let (cpu, gpu) = (Device::flex(), parse("wgpu").expect("built with wgpu"));
    let unet = UNetConfig { model_channels: 32, ..UNetConfig::pusht_latent(8) }.init(&cpu);
    let noise = Tensor::<5>::random([2, 8, 4, 12, 12], Distribution::Default, &cpu);
    let hist = Tensor::<5>::random([2, 8, 4, 12, 12], Distribution::Default, &cpu);
    let act = Tensor::<3>::random([2, 4, 2], Distribution::Default, &cpu);
    let want = unet.forward(noise.clone(), hist.clone(), act.clone(), None, None); // [2, 8, 4, 12, 12]
    let got =
        unet.fork(&gpu).forward(noise.to_device(&gpu), hist.to_device(&gpu), act.to_device(&gpu), None, None);
    let got = got.to_device(&cpu);
    let scale: f32 = want.clone().abs().max().into_scalar();
    let diff: f32 = (want - got).abs().max().into_scalar();
    assert!(scale > 0.0 && diff <= 1e-4 * scale.max(1.0), "wgpu differs from Flex by {diff} (scale {scale})");
}
