//! Round trips of the replay-buffer layout.

use super::*;
use serde_json::json;

fn spec() -> ReplaySpec {
    ReplaySpec { image_hw: [4, 5], action_dim: 2, state_dim: 3, extras: vec!["coverage".into()] }
}

fn episode(steps: usize, base: f32) -> EpisodeArrays {
    EpisodeArrays {
        img: (0..steps * 4 * 5 * 3).map(|i| (i % 251) as u8).collect(),
        action: (0..steps * 2).map(|i| base + i as f32).collect(),
        state: (0..steps * 3).map(|i| base - i as f32).collect(),
        extras: vec![(0..steps).map(|i| i as f32 / 10.0).collect()],
    }
}

#[test]
fn write_then_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("d.zarr");
    let mut w = ReplayWriter::create(&path, spec(), false).unwrap();
    // 150 + 7 steps: the image array spans two chunks of 100 rows, the last one padded.
    w.append(&episode(150, 0.0)).unwrap();
    w.append(&episode(7, 1000.0)).unwrap();
    w.finish(&json!({"evalharness": {"scenario": "test"}})).unwrap();
    assert!(!dir.path().join("d.zarr.partial").exists());

    let r = ReplayReader::open(&path).unwrap();
    assert_eq!(r.episodes(), 2);
    assert_eq!(r.steps(), 157);
    assert_eq!(r.episode_range(1), 150..157);
    let img = r.img.read_rows(99, 101).unwrap();
    let expect: Vec<u8> = (99 * 60..101 * 60).map(|i| (i % 251) as u8).collect();
    assert_eq!(img, expect);
    let actions = r.action.read_f64().unwrap();
    assert_eq!(actions[300], 1000.0); // first action of episode 2
    assert_eq!(actions[301], 1001.0);
    let cov = r.extra("coverage").unwrap().unwrap();
    assert_eq!(cov.len(), 157);
    assert!((cov[151] - 0.1).abs() < 1e-6);
    assert_eq!(r.attrs["evalharness"]["scenario"], "test");
    assert!(r.extra("nothing").unwrap().is_none());
}

#[test]
fn existing_output_is_refused_without_force() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("d.zarr");
    ReplayWriter::create(&path, spec(), false).unwrap().finish(&json!({})).unwrap();
    assert!(matches!(ReplayWriter::create(&path, spec(), false), Err(ReplayError::Exists(_))));
    assert!(ReplayWriter::create(&path, spec(), true).is_ok());
}

#[test]
fn not_a_dataset_is_a_layout_error() {
    let dir = tempfile::tempdir().unwrap();
    let err = ReplayReader::open(dir.path()).err().unwrap().to_string();
    assert!(err.contains("not a replay-buffer dataset"), "{err}");
    // A group with an image array but no actions names what is missing.
    let path = dir.path().join("d.zarr");
    ReplayWriter::create(&path, spec(), false).unwrap().finish(&json!({})).unwrap();
    std::fs::remove_dir_all(path.join("data/action")).unwrap();
    let err = ReplayReader::open(&path).err().unwrap().to_string();
    assert!(err.contains("data/action"), "{err}");
}

#[test]
fn blosc_lz4_fixture_from_zarr_python_reads() {
    // Written by zarr-python 2 with its default compressor, Blosc(lz4, clevel 5, byte
    // shuffle); see tests/fixtures/make_blosc_fixture.py.
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/blosc_lz4.zarr");
    let r = ReplayReader::open(&p).unwrap();
    assert_eq!(r.episodes(), 2);
    let action = r.action.read_f64().unwrap();
    // action[i] = [i, 2 i] * 0.5 as float32.
    for (i, pair) in action.chunks(2).enumerate() {
        assert_eq!(pair, [i as f64 * 0.5, i as f64]);
    }
    let img = r.img.read_rows(0, r.steps()).unwrap();
    assert!(img.iter().enumerate().all(|(i, &v)| v == (i % 7) as u8));
}

#[test]
fn episodes_and_spec_read_back_as_written() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("d.zarr");
    let mut w = ReplayWriter::create(&path, spec(), false).unwrap();
    let (a, b) = (episode(150, 0.0), episode(7, 1000.0));
    w.append(&a).unwrap();
    w.append(&b).unwrap();
    w.finish(&json!({})).unwrap();
    let r = ReplayReader::open(&path).unwrap();
    assert_eq!(r.spec().unwrap(), spec());
    let got = r.read_episode(1, &["coverage".into()]).unwrap();
    assert_eq!(got.img, b.img);
    assert_eq!(got.action, b.action);
    assert_eq!(got.state, b.state);
    assert_eq!(got.extras, b.extras);
    let err = r.read_episode(0, &["reward".into()]).err().unwrap().to_string();
    assert!(err.contains("data/reward"), "{err}");
}

/// A GPC-style group at `path`: `steps` rows of `hw`-sided float32 images (value `v`), 2-D
/// actions and 5-D states, one episode per 5 steps.
fn gpc_group(path: &Path, steps: usize, hw: usize, v: f32) {
    write_group(path, None).unwrap();
    write_group(&path.join("data"), None).unwrap();
    write_group(&path.join("meta"), None).unwrap();
    let d = path.join("data");
    let mut img = ArrayWriter::create(&d.join("img"), DType::F32, &[hw, hw, 3], 7).unwrap();
    img.append(&f32_bytes(&vec![v; steps * hw * hw * 3])).unwrap();
    img.finish().unwrap();
    let mut action = ArrayWriter::create(&d.join("action"), DType::F32, &[2], 100).unwrap();
    action.append(&f32_bytes(&(0..steps * 2).map(|i| i as f32).collect::<Vec<_>>())).unwrap();
    action.finish().unwrap();
    let mut state = ArrayWriter::create(&d.join("state"), DType::F32, &[5], 100).unwrap();
    state.append(&f32_bytes(&vec![1.0; steps * 5])).unwrap();
    state.finish().unwrap();
    let ends: Vec<i64> = (1..=steps / 5).map(|e| (e * 5) as i64).collect();
    let mut e = ArrayWriter::create(&path.join("meta/episode_ends"), DType::I64, &[], ends.len()).unwrap();
    e.append(&ends.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>()).unwrap();
    e.finish().unwrap();
}

#[test]
fn a_folder_of_groups_reads_as_one_dataset_with_float_images_as_bytes() {
    // GPC's world-model data: a folder of .zarr groups read in name order, images float32
    // in [0, 255]. b.zarr (10 steps, 2 episodes) sorts before c.zarr (15 steps, 3 episodes).
    let dir = tempfile::tempdir().unwrap();
    gpc_group(&dir.path().join("c.zarr"), 15, 4, 200.4);
    gpc_group(&dir.path().join("b.zarr"), 10, 4, 12.6);
    std::fs::write(dir.path().join("notes.txt"), "not a group").unwrap();
    let r = ReplayReader::open(dir.path()).unwrap();
    assert_eq!((r.episodes(), r.steps()), (5, 25));
    assert_eq!(r.episode_ends, [5, 10, 15, 20, 25]);
    assert_eq!(r.img.shape(), [25, 4, 4, 3]);
    // Rows 8..12 span both groups: 12.6 rounds to 13, 200.4 to 200.
    let img = r.img.read_rows(8, 12).unwrap();
    assert_eq!(img.len(), 4 * 48);
    assert!(img[..96].iter().all(|&v| v == 13) && img[96..].iter().all(|&v| v == 200));
    // Episode 3 is c.zarr's second: rows 5..10 there, actions 10..20 of that group.
    let ep = r.read_episode(3, &[]).unwrap();
    assert_eq!(ep.action[0], 10.0);
    assert!(ep.img.iter().all(|&v| v == 200));
    assert_eq!(r.spec().unwrap().state_dim, 5);
    assert_eq!(r.action.read_f64().unwrap().len(), 50);

    // Groups that disagree are refused naming the group.
    gpc_group(&dir.path().join("d.zarr"), 5, 6, 1.0);
    let err = ReplayReader::open(dir.path()).err().unwrap().to_string();
    assert!(err.contains("d.zarr") && err.contains("data/img"), "{err}");
}

#[test]
fn float_images_outside_0_255_are_refused_by_group_and_row() {
    let dir = tempfile::tempdir().unwrap();
    gpc_group(&dir.path().join("a.zarr"), 5, 2, 300.0);
    let r = ReplayReader::open(dir.path()).unwrap();
    let err = r.img.read_rows(0, 5).err().unwrap().to_string();
    assert!(err.contains("a.zarr") && err.contains("row 0") && err.contains("300"), "{err}");
    // An empty folder is not a dataset.
    let empty = tempfile::tempdir().unwrap();
    let err = ReplayReader::open(empty.path()).err().unwrap().to_string();
    assert!(err.contains("no *.zarr groups"), "{err}");
}
