//! `evalharness collect` and `dataset info`.

use crate::util::{expect_code, read_json, run, tree_bytes};

fn collect(out: &std::path::Path, jobs: &str) {
    let o = out.to_str().unwrap();
    let args = [
        "collect",
        "--episodes",
        "4",
        "--seed-start",
        "0",
        "--max-steps",
        "25",
        "--mix",
        "expert=0.5,explore=0.5",
        "--jobs",
        jobs,
        "--out",
        o,
    ];
    expect_code(&run(&args), 0);
}

#[test]
fn collect_is_identical_for_any_job_count_and_info_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.zarr"), dir.path().join("b.zarr"));
    collect(&a, "1");
    collect(&b, "2");
    let (ta, tb) = (tree_bytes(&a), tree_bytes(&b));
    assert!(ta.iter().any(|(p, _)| p == "data/img/.zarray"));
    assert_eq!(ta, tb, "--jobs 1 and --jobs 2 datasets differ");

    let (stdout, _) = expect_code(&run(&["dataset", "info", "--json", a.to_str().unwrap()]), 0);
    let info: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(info["episodes"], 4);
    assert_eq!(info["image"], serde_json::json!([96, 96, 3]));
    assert_eq!(info["state_dim"], 8);
    assert_eq!(info["score_source"], "data/coverage");
    let attrs = read_json(&a.join(".zattrs"));
    let eps = attrs["evalharness"]["episodes"].as_array().unwrap();
    let steps: u64 = eps.iter().map(|e| e["steps"].as_u64().unwrap()).sum();
    assert_eq!(info["steps"].as_u64().unwrap(), steps);
    let behaviours = info["behaviours"].as_object().unwrap();
    let counted: u64 = behaviours.values().map(|v| v["episodes"].as_u64().unwrap()).sum();
    assert_eq!(counted, 4);

    let (text, _) = expect_code(&run(&["dataset", "info", a.to_str().unwrap()]), 0);
    assert!(text.contains("episodes   4"), "{text}");
}

#[test]
fn info_on_something_else_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let (_, err) = expect_code(&run(&["dataset", "info", dir.path().to_str().unwrap()]), 2);
    assert!(err.contains("not a replay-buffer dataset"), "{err}");
    let missing = dir.path().join("nope.zarr");
    let (_, err) = expect_code(&run(&["dataset", "info", missing.to_str().unwrap()]), 2);
    assert!(err.contains("nope.zarr"), "{err}");
}

#[test]
fn bad_mix_is_rejected_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("d.zarr");
    let (_, err) =
        expect_code(&run(&["collect", "--mix", "expert=1,teleop=1", "--out", o.to_str().unwrap()]), 2);
    assert!(err.contains("teleop"), "{err}");
    assert!(!o.exists());
}

#[test]
fn merge_concatenates_episodes_and_keeps_their_origin() {
    use harness::replay::ReplayReader;
    let dir = tempfile::tempdir().unwrap();
    let (a, b, m) = (dir.path().join("a.zarr"), dir.path().join("b.zarr"), dir.path().join("m.zarr"));
    collect(&a, "2");
    let args = ["collect", "--episodes", "2", "--seed-start", "10", "--max-steps", "20", "--mix", "expert=1"];
    expect_code(&run(&[&args[..], &["--noise", "30", "--out", b.to_str().unwrap()]].concat()), 0);
    let (ps, pb, pm) = (a.to_str().unwrap(), b.to_str().unwrap(), m.to_str().unwrap());
    let (stdout, _) = expect_code(&run(&["dataset", "merge", ps, pb, "--out", pm]), 0);
    assert!(stdout.contains("6 episodes"), "{stdout}");

    let (ra, rb, rm) =
        (ReplayReader::open(&a).unwrap(), ReplayReader::open(&b).unwrap(), ReplayReader::open(&m).unwrap());
    assert_eq!(rm.steps(), ra.steps() + rb.steps());
    assert_eq!(rm.spec().unwrap(), ra.spec().unwrap());
    let extras = ["coverage".to_string()];
    // Episode 4 of the merge is episode 0 of b, byte for byte.
    let (got, want) = (rm.read_episode(4, &extras).unwrap(), rb.read_episode(0, &extras).unwrap());
    assert_eq!(
        (got.img, got.action, got.state, got.extras),
        (want.img, want.action, want.state, want.extras)
    );
    let eps = rm.attrs["evalharness"]["episodes"].as_array().unwrap().clone();
    assert_eq!(eps.iter().map(|e| e["source"].as_u64().unwrap()).collect::<Vec<_>>(), [0, 0, 0, 0, 1, 1]);
    assert_eq!(eps[4]["seed"], 10);
    // Noisy experts are labelled as such, so `train policy --behaviour expert` skips them.
    assert_eq!(eps[4]["behaviour"], "expert+noise30");
    assert_eq!(rm.attrs["evalharness"]["merged_from"][1]["attrs"]["noise"], 30.0);

    let (_, err) = expect_code(&run(&["dataset", "merge", ps, dir.path().to_str().unwrap(), "--out", pm]), 2);
    assert!(err.contains(dir.path().to_str().unwrap()), "{err}");
}
