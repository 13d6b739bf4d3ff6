//! The DriftWorld import against PyTorch: fixtures written by `scripts/fixtures/driftworld_wm.py`
//! (evalharness's own PyTorch re-implementation of the official U-Net, checked there against the
//! official module: same 436 keys and shapes, identical outputs), and files that must be refused.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};

use nn::ImportError;
use nn::import::tensors::Source;

use super::driftworld::{Preset, Weights, import, permute_qkv, plan};
use crate::unet::UNetConfig;
use crate::unet::cpu::CpuUNet;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/driftworld").join(name)
}

/// The fixture's reference tensors (`wm_io.pth`): values and shape.
fn io(name: &str) -> (Vec<f32>, Vec<usize>) {
    let src = Source::open(&fixture("wm_io.pth"), None, "").unwrap_or_else(|e| panic!("{e}"));
    let shape = src.shapes()[name].clone();
    (src.f32s(name, &shape).unwrap_or_else(|e| panic!("{e}")), shape)
}

fn tensor<const D: usize>(name: &str) -> Tensor<D> {
    let (v, s) = io(name);
    Tensor::from_data(TensorData::new(v, s), &Device::flex())
}

fn max_abs(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

#[test]
fn the_fixture_predicts_what_pytorch_predicts() {
    for (weights, want) in [(Weights::Ema, "ema"), (Weights::Inner, "inner")] {
        let m = import(&fixture("wm.pth"), weights, Preset::Pusht, Some(16), "test".into())
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(m.record.tensors, 436);
        assert_eq!(m.record.step, Some(4321));
        assert_eq!(m.record.parameters, m.unet.num_params());
        assert_eq!(m.unet.num_params(), 908_193); // the generator's count per copy
        let (noise, history, actions) =
            (tensor::<5>("noise"), tensor::<5>("history"), tensor::<3>("actions"));
        let (want, _) = io(want);
        let got = m.unet.forward(noise.clone(), history.clone(), actions.clone(), None, None);
        let got = got.into_data().try_to_vec::<f32>().unwrap_or_default();
        let d = max_abs(&got, &want);
        assert!(d <= 1e-5, "burn's U-Net differs from PyTorch by {d}");
        // The CPU kernels that `rank` runs on.
        let cpu = CpuUNet::new(&m.unet).unwrap_or_else(|e| panic!("{e}"));
        let x = m.unet.inputs(noise, history, actions.clone(), None);
        let dims = x.dims();
        let emb = m.unet.embedding(actions, None, None).into_data().try_to_vec::<f32>().unwrap_or_default();
        let got = cpu.forward(&x.into_data().try_to_vec::<f32>().unwrap_or_default(), &emb, dims);
        let d = max_abs(&got, &want);
        assert!(d <= 1e-5, "the CPU kernels differ from PyTorch by {d}");
    }
}

/// The error of importing a refused fixture, as text.
fn refused(name: &str) -> String {
    match import(&fixture(name), Weights::Ema, Preset::Pusht, None, "test".into()) {
        Ok(_) => panic!("{name} was imported"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn a_good_small_file_imports() {
    let m = import(&fixture("micro.pth"), Weights::Ema, Preset::Pusht, None, "test".into())
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(m.config.unet.channel_mult, vec![1]);
    assert_eq!(m.config.unet.res_blocks, 1);
    assert_eq!(m.config.unet.emb_dim, 8);
}

#[test]
fn damaged_files_are_refused_naming_the_key() {
    let e = refused("micro_missing_key.pth");
    assert!(e.contains("`model.ema_model.middle_block.0.in_layers.0.weight` is missing"), "{e}");
    let e = refused("micro_wrong_shape.pth");
    assert!(e.contains("`model.ema_model.middle_block.0.emb_layers.1.weight` has shape [63, 8]"), "{e}");
    let e = refused("micro_float64.pth");
    assert!(e.contains("`model.ema_model.out.0.weight` is f64"), "{e}");
    // qkv.weight [96, 32, 1] and proj_out.weight [32, 32, 1] exchanged.
    let e = refused("micro_qkv_swapped.pth");
    assert!(
        e.contains("`model.ema_model.middle_block.1.qkv.weight` has shape [32, 32, 1], expected [96, 32, 1]"),
        "{e}"
    );
    let e = refused("micro_unexpected_key.pth");
    assert!(e.contains("unexpected key(s) model.ema_model.middle_block.1.extra.weight"), "{e}");
    // The micro files hold no inner copy.
    let e = match import(&fixture("micro.pth"), Weights::Inner, Preset::Pusht, None, "test".into()) {
        Err(e @ ImportError::Missing { .. }) => e.to_string(),
        other => panic!("{:?}", other.err()),
    };
    assert!(e.contains("`model.inner_model.*` is missing"), "{e}");
}

#[test]
fn a_preset_or_frame_size_that_does_not_fit_the_file_is_refused() {
    // The fixture reads 2-D actions (Push-T's); Lift's preset has 7.
    let e = import(&fixture("wm.pth"), Weights::Ema, Preset::Lift, None, "test".into())
        .err()
        .map(|e| e.to_string());
    let e = e.unwrap_or_default();
    assert!(
        e.contains("`model.ema_model.action_embed.0.weight` reads 2-D actions") && e.contains("7-D"),
        "{e}"
    );
    // 4 levels halve the frame 3 times: 20 is not a multiple of 8.
    let e = import(&fixture("wm.pth"), Weights::Ema, Preset::Pusht, Some(20), "test".into())
        .err()
        .map(|e| e.to_string());
    assert!(e.unwrap_or_default().contains("a multiple of 8"));
}

#[test]
fn a_file_that_is_not_a_checkpoint_is_refused() {
    let dir = std::env::temp_dir().join(format!("eh-import-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
    let path = dir.join("not.pth");
    std::fs::write(&path, b"not a zip").unwrap_or_else(|e| panic!("{e}"));
    let e = match import(&path, Weights::Ema, Preset::Pusht, None, "test".into()) {
        Err(e @ ImportError::Read { .. }) => e.to_string(),
        other => panic!("{:?}", other.err()),
    };
    assert!(e.contains("not.pth"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_official_pusht_manifest_maps_every_key_once() {
    // Names and shapes of the released Push-T checkpoint's `ema_model.*` (436 tensors), read
    // from the official module with random weights (shared research notes).
    let text =
        std::fs::read_to_string(fixture("pusht_wm_ema_model_keys.tsv")).unwrap_or_else(|e| panic!("{e}"));
    let shapes: BTreeMap<String, Vec<usize>> = text
        .lines()
        .map(|l| {
            let (k, s) = l.split_once('\t').unwrap_or_else(|| panic!("{l}"));
            let dims =
                s.trim_matches(|c| c == '(' || c == ')').split(',').filter_map(|d| d.trim().parse().ok());
            (k.trim_start_matches("ema_model.").to_string(), dims.collect())
        })
        .collect();
    assert_eq!(shapes.len(), 436);
    let p = plan(&shapes, Preset::Pusht, Path::new("manifest")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(p.unet, UNetConfig::pusht_pixel().with_frame_attention_norm(Some(true)));
    let keys: BTreeSet<&str> = p.entries.iter().map(|e| e.key.as_str()).collect();
    assert_eq!(keys.len(), p.entries.len(), "a key mapped twice");
    assert_eq!(keys, shapes.keys().map(String::as_str).collect::<BTreeSet<_>>());
    // Every parameter of the full-size U-Net (8,375,201) gets exactly one key, of its shape.
    let unet = p.unet.init(&Device::flex());
    assert_eq!(unet.num_params(), 8_375_201);
    let ours = nn::import::place::shapes(&unet);
    let targets: BTreeSet<&str> = p.entries.iter().map(|e| e.ours.as_str()).collect();
    assert_eq!(targets, ours.keys().map(String::as_str).collect::<BTreeSet<_>>());
    for e in &p.entries {
        let mut s = ours[&e.ours].clone();
        if e.transform == super::driftworld::Transform::Transpose {
            s.reverse();
        }
        assert_eq!(s, shapes[&e.key], "{}", e.key);
    }
}

#[test]
fn qkv_rows_move_from_head_major_to_qkv_major() {
    // 2 heads of d = 1, rows of 2 values: head-major [q0 k0 v0 q1 k1 v1] → [q0 q1 k0 k1 v0 v1].
    let old = [10., 11., 20., 21., 30., 31., 40., 41., 50., 51., 60., 61.];
    let new = permute_qkv(&old, 2, 2);
    assert_eq!(new, vec![10., 11., 40., 41., 20., 21., 50., 51., 30., 31., 60., 61.]);
}

/// Built with `--features wgpu` only, where a Vulkan driver is (lavapipe on a CPU:
/// `apt-get install mesa-vulkan-drivers`): the imported fixture gives on burn's wgpu backend
/// what it gives on the CPU and what PyTorch gave (the GPU path a paper-scale user takes).
#[cfg(feature = "wgpu")]
#[test]
fn the_imported_model_predicts_on_wgpu_what_it_predicts_on_the_cpu() {
    let m = import(&fixture("wm.pth"), Weights::Ema, Preset::Pusht, Some(16), "test".into())
        .unwrap_or_else(|e| panic!("{e}"));
    let gpu = nn::device::parse("wgpu").expect("built with wgpu");
    let (noise, history, actions) = (tensor::<5>("noise"), tensor::<5>("history"), tensor::<3>("actions"));
    let cpu_out = m.unet.forward(noise.clone(), history.clone(), actions.clone(), None, None);
    let cpu_out = cpu_out.into_data().try_to_vec::<f32>().unwrap_or_default();
    let gpu_out = m.unet.fork(&gpu).forward(
        noise.to_device(&gpu),
        history.to_device(&gpu),
        actions.to_device(&gpu),
        None,
        None,
    );
    let gpu_out = gpu_out.into_data().try_to_vec::<f32>().unwrap_or_default();
    let (want, _) = io("ema");
    let (d_cpu, d_torch) = (max_abs(&gpu_out, &cpu_out), max_abs(&gpu_out, &want));
    println!("wgpu against the CPU build: {d_cpu:e}; against PyTorch: {d_torch:e}");
    assert!(
        d_cpu <= 1e-4 && d_torch <= 1e-4,
        "wgpu differs: {d_cpu} from the CPU build, {d_torch} from PyTorch"
    );
}
