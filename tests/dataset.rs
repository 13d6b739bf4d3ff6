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

#[test]
fn collect_policy_records_the_rollouts_that_simulate_scores() {
    use harness::replay::ReplayReader;
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("scripted");
    let s = set.to_str().unwrap();
    expect_code(&run(&["scripted", "--out", s, "--noise", "0,200", "--lag", "0"]), 0);
    let common = ["--policy", s, "--episodes", "2", "--seed-start", "7", "--max-steps", "24"];
    let (a, b) = (dir.path().join("a.zarr"), dir.path().join("b.zarr"));
    for (out, jobs) in [(&a, "1"), (&b, "2")] {
        let args = [&["collect"][..], &common, &["--jobs", jobs, "--out", out.to_str().unwrap()]].concat();
        let (stdout, _) = expect_code(&run(&args), 0);
        assert!(stdout.contains("4 episodes of 2 checkpoint(s)"), "{stdout}");
    }
    assert_eq!(tree_bytes(&a), tree_bytes(&b), "--jobs 1 and --jobs 2 datasets differ");

    // The same episodes as `simulate --policy` (rank's MuJoCo branch): same seeds, same scores.
    let sim = dir.path().join("sim");
    expect_code(&run(&[&["simulate"][..], &common, &["--out", sim.to_str().unwrap()]].concat()), 0);
    let rows: Vec<serde_json::Value> = std::fs::read_to_string(sim.join("episodes.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let r = ReplayReader::open(&a).unwrap();
    let eps = r.attrs["evalharness"]["episodes"].as_array().unwrap().clone();
    assert_eq!(eps.len(), 4);
    for (e, row) in eps.iter().zip(&rows) {
        assert_eq!((&e["behaviour"], &e["seed"]), (&row["policy"], &row["seed"]));
        assert_eq!((&e["score"], &e["steps"]), (&row["score"], &row["steps"]), "{e} vs {row}");
    }
    // One observation per step, taken before the action: the first state row is the
    // reset pose, and the first image is the frame of that pose (not all white).
    let extras = ["coverage".to_string()];
    let ep = r.read_episode(0, &extras).unwrap();
    let steps = eps[0]["steps"].as_u64().unwrap() as usize;
    assert_eq!((ep.img.len(), ep.action.len(), ep.state.len()), (steps * 96 * 96 * 3, steps * 2, steps * 8));
    assert!(ep.img[..96 * 96 * 3].iter().any(|&v| v < 200));
    let max_cov = ep.extras[0].iter().fold(0f32, |m, &c| m.max(c));
    let score = eps[0]["score"].as_f64().unwrap();
    assert!((f64::from(max_cov) / 0.95).min(1.0) - score < 1e-6, "coverage {max_cov} vs score {score}");
    let origin = &r.attrs["evalharness"];
    assert_eq!(origin["checkpoints"].as_array().unwrap().len(), 2);

    // The expert's perturbations do not apply, and --policy excludes --mix.
    let o = dir.path().join("c.zarr");
    let o = o.to_str().unwrap();
    let (_, err) = expect_code(&run(&["collect", "--policy", s, "--noise", "5", "--out", o]), 2);
    assert!(err.contains("--noise"), "{err}");
    expect_code(&run(&["collect", "--policy", s, "--mix", "expert=1", "--out", o]), 2);
}

/// Rewrites evalharness dataset `src` as GPC stores world-model data: a group without
/// evalharness's attributes, float32 images in [0, 255] and a 5-wide state (agent, block).
fn as_gpc_group(src: &std::path::Path, out: &std::path::Path, episodes: std::ops::Range<usize>) {
    use harness::zarr::{ArrayWriter, DType, write_group};
    let r = harness::replay::ReplayReader::open(src).unwrap();
    let rows = r.episode_range(episodes.start).start..r.episode_range(episodes.end - 1).end;
    let f32s = |v: Vec<f64>| v.into_iter().flat_map(|x| (x as f32).to_le_bytes()).collect::<Vec<u8>>();
    for g in ["", "data", "meta"] {
        write_group(&out.join(g), None).unwrap();
    }
    let write = |name: &str, dtype, row: &[usize], bytes: Vec<u8>| {
        let mut w = ArrayWriter::create(&out.join(name), dtype, row, 64).unwrap();
        w.append(&bytes).unwrap();
        w.finish().unwrap();
    };
    let img = r.img.read_rows(rows.start, rows.end).unwrap();
    write("data/img", DType::F32, &[96, 96, 3], f32s(img.into_iter().map(f64::from).collect()));
    write("data/action", DType::F32, &[2], f32s(r.action.read_rows_f64(rows.start, rows.end).unwrap()));
    let state = r.state.read_rows_f64(rows.start, rows.end).unwrap();
    write("data/state", DType::F32, &[5], f32s(state.chunks(8).flat_map(|s| s[..5].to_vec()).collect()));
    let ends: Vec<u8> =
        episodes.map(|i| (r.episode_range(i).end - rows.start) as i64).flat_map(i64::to_le_bytes).collect();
    write("meta/episode_ends", DType::I64, &[], ends);
}

#[test]
fn a_gpc_data_folder_opens_as_one_dataset_and_evaluates_as_the_original() {
    // GPC's world-model data is a folder of zarr groups with float32 images. The same four
    // 70-step episodes as one evalharness dataset and as such a folder (two groups) must read
    // the same: `dataset info` counts them, `wm eval` of the shipped model scores them alike.
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("src.zarr");
    let args = ["collect", "--episodes", "4", "--max-steps", "70", "--mix", "explore=1", "--out"];
    expect_code(&run(&[&args[..], &[src.to_str().unwrap()]].concat()), 0);
    let folder = dir.path().join("gpc");
    as_gpc_group(&src, &folder.join("episodes_00.zarr"), 0..1);
    as_gpc_group(&src, &folder.join("episodes_01.zarr"), 1..4);
    let (stdout, _) = expect_code(&run(&["dataset", "info", "--json", folder.to_str().unwrap()]), 0);
    let info: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!((info["episodes"].as_u64(), info["state_dim"].as_u64()), (Some(4), Some(5)), "{info}");
    assert_eq!(info["steps"].as_u64(), Some(280));

    // A world model that predicts the whole frame (the shipped default draws the goal back from
    // the state, which GPC data does not record).
    let wm = std::path::Path::new(crate::util::PUSHT).join("world_model_mse");
    let eval = |data: &std::path::Path, out: &std::path::Path| {
        let a = ["wm", "eval", "--world-model", wm.to_str().unwrap(), "--data", data.to_str().unwrap()];
        let b = ["--all-episodes", "--episodes", "2", "--full-episodes", "0", "--out", out.to_str().unwrap()];
        expect_code(&run(&[&a[..], &b[..]].concat()), 0);
        read_json(&out.join("eval.json"))["models"][0].clone()
    };
    let (from_src, from_folder) = (eval(&src, &dir.path().join("e1")), eval(&folder, &dir.path().join("e2")));
    assert_eq!(from_src["frames"], from_folder["frames"]);
    assert_eq!(from_src["psnr"], from_folder["psnr"], "{from_src} vs {from_folder}");
}

/// A Lift or Can dataset collected before 2026-12-03 left its rendering out of
/// `scenario_config` when it was the default, which was then robosuite's: it merges with data
/// rendered robosuite's way (and the merged dataset writes that rendering out), not with data
/// rendered another way.
#[test]
fn an_older_dataset_merges_as_the_rendering_it_was_made_with() {
    let dir = tempfile::tempdir().unwrap();
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let cheap = dir.path().join("can_cheap.toml");
    std::fs::write(&cheap, "name = \"can\"\n[visual]\nsamples = 0\nreflections = false\n").unwrap();
    let robosuite = root.join("scenarios/can_robosuite.toml");
    let collect = |scene: &std::path::Path, seed: &str, out: &std::path::Path| {
        let args =
            ["collect", "--scenario", scene.to_str().unwrap(), "--episodes", "1", "--seed-start", seed];
        expect_code(&run(&[&args[..], &["--max-steps", "2", "--out", out.to_str().unwrap()]].concat()), 0);
    };
    let (old, new, other) =
        (dir.path().join("old.zarr"), dir.path().join("new.zarr"), dir.path().join("cheap.zarr"));
    collect(&robosuite, "0", &old);
    collect(&robosuite, "1", &new);
    collect(&cheap, "2", &other);
    // `old` as written before 2026-12-03: the same, without `visual`.
    let attrs = old.join(".zattrs");
    let mut a = read_json(&attrs);
    let visual = a["evalharness"]["scenario_config"]["visual"].clone();
    assert_eq!(visual["samples"], 4, "{a}");
    a["evalharness"]["scenario_config"].as_object_mut().unwrap().remove("visual");
    std::fs::write(&attrs, a.to_string()).unwrap();
    let merged = dir.path().join("merged.zarr");
    let m = merged.to_str().unwrap();
    expect_code(&run(&["dataset", "merge", old.to_str().unwrap(), new.to_str().unwrap(), "--out", m]), 0);
    assert_eq!(read_json(&merged.join(".zattrs"))["evalharness"]["scenario_config"]["visual"], visual);
    let (_, err) = expect_code(
        &run(&["dataset", "merge", old.to_str().unwrap(), other.to_str().unwrap(), "--out", m]),
        2,
    );
    assert!(err.contains("scenario_config differs"), "{err}");
}
