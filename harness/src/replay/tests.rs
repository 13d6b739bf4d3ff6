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
