//! The bad-input and crash probe, as tests: each case reproduces one defect the probe
//! found (data lost, results silently wrong, a crash or hang, a vague message) and
//! checks the behaviour `docs/guarantees.md` promises instead.

use std::path::{Path, PathBuf};
use std::process::Stdio;

use crate::util::{
    copy_dir, evalharness, expect_code, read_json, results, run, s, scenario_variant, tree_bytes, with_flag,
};

/// Two scripted checkpoints and a copy of the shipped world model (see
/// [`crate::util::pusht_inputs`]); returns (policy set, world model).
fn inputs(dir: &Path) -> (PathBuf, PathBuf) {
    crate::util::pusht_inputs(dir)
}

/// A tiny paired run (see [`crate::util::tiny_rank_args`]).
fn rank_args<'a>(set: &'a Path, wm: &'a Path, out: &'a Path) -> Vec<&'a str> {
    crate::util::tiny_rank_args(set, wm, out)
}

#[test]
fn force_and_merge_never_destroy_inputs_or_a_finished_run() {
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    let prev = tmp.path().join("prev");
    expect_code(&run(&rank_args(&set, &wm, &prev)), 0);
    let before = tree_bytes(&prev);
    // D1: a mistyped --policies with --force used to empty the previous run first.
    let typo = tmp.path().join("mistyped");
    let mut args = rank_args(&typo, &wm, &prev);
    args.push("--force");
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("mistyped"), "{err}");
    assert_eq!(tree_bytes(&prev), before, "a refused --force run changed the previous run");
    // D1: --out equal to, inside or containing an input is refused before anything is touched.
    let set_before = tree_bytes(&set);
    for out in [set.clone(), set.join("noise000-lag0").join("run"), tmp.path().to_path_buf()] {
        let mut args = rank_args(&set, &wm, &out);
        args.push("--force");
        let (_, err) = expect_code(&run(&args), 2);
        assert!(err.contains("the input --policies") || err.contains("the input --world-model"), "{err}");
    }
    assert_eq!(tree_bytes(&set), set_before, "the policies were touched");
    // D1 for the trainers: a bad --data with --force keeps the run it would replace.
    let ae = tmp.path().join("ae_run");
    std::fs::create_dir_all(&ae).unwrap();
    std::fs::write(ae.join("state.json"), b"{\"step\": 1}").unwrap();
    let args = ["train", "autoencoder", "--data", s(&typo), "--out", s(&ae), "--steps", "1", "--force"];
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("--data") && err.contains("mistyped"), "{err}");
    assert!(ae.join("state.json").is_file());

    // D2: merging datasets into one of the inputs is refused; the input stays whole.
    let data: Vec<PathBuf> = (0..2).map(|i| tmp.path().join(format!("d{i}.zarr"))).collect();
    for (i, d) in data.iter().enumerate() {
        let seed = (i * 10).to_string();
        let args = ["collect", "--episodes", "1", "--max-steps", "5", "--seed-start", &seed, "--out", s(d)];
        expect_code(&run(&args), 0);
    }
    let d0 = tree_bytes(&data[0]);
    let args = ["dataset", "merge", s(&data[0]), s(&data[1]), "--out", s(&data[0]), "--force"];
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("is the input dataset"), "{err}");
    assert_eq!(tree_bytes(&data[0]), d0);
    assert!(!tmp.path().join("d0.zarr.partial").exists());

    // D2 and D7: shards. Merging into a shard, a missing shard, a repeated one: refused.
    let shards: Vec<PathBuf> = (0..2).map(|i| tmp.path().join(format!("sh{i}"))).collect();
    for (i, d) in shards.iter().enumerate() {
        let spec = format!("{i}/2");
        let mut args = rank_args(&set, &wm, d);
        args.extend(["--shard", &spec]);
        expect_code(&run(&args), 0);
    }
    let sh0 = tree_bytes(&shards[0]);
    let merged = tmp.path().join("merged");
    let cases: [(Vec<&str>, &str); 3] = [
        (vec![s(&shards[0]), s(&shards[1]), "--out", s(&shards[0]), "--force"], "is the input shard"),
        (vec![s(&shards[0]), "--out", s(&merged)], "shard 1 of 2 missing"),
        (vec![s(&shards[0]), s(&shards[0]), "--out", s(&merged)], "are both shard 0/2"),
    ];
    for (args, want) in cases {
        let (_, err) = expect_code(&run(&[&["merge", "--no-report"][..], &args[..]].concat()), 2);
        assert!(err.contains(want), "{err}");
    }
    assert_eq!(tree_bytes(&shards[0]), sh0);
    assert!(!merged.exists());
    // The complete set merges into what the unsharded run wrote.
    expect_code(&run(&["merge", s(&shards[0]), s(&shards[1]), "--out", s(&merged), "--no-report"]), 0);
    assert_eq!(results(&merged), results(&prev));

    // The folder an interrupted --force run set aside is never overwritten by another.
    let aside = tmp.path().join("prev.replaced");
    std::fs::create_dir_all(&aside).unwrap();
    std::fs::write(aside.join("results.json"), b"{}").unwrap();
    let mut args = rank_args(&set, &wm, &prev);
    args.push("--force");
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("prev.replaced") && err.contains("interrupted --force run"), "{err}");
    assert_eq!(std::fs::read(aside.join("results.json")).unwrap(), b"{}");
    assert_eq!(tree_bytes(&prev), before);
    std::fs::remove_dir_all(&aside).unwrap();
    // A --force run that succeeds replaces the old run and leaves nothing aside.
    let mut args = rank_args(&set, &wm, &prev);
    args.extend(["--force", "--seed", "1"]);
    expect_code(&run(&args), 0);
    assert_eq!(read_json(&prev.join("results.json"))["policies"].as_array().unwrap().len(), 2);
    assert!(!tmp.path().join("prev.replaced").exists());
}

#[test]
fn a_failing_world_model_stops_the_run_once_and_a_forced_run_restores_the_old_one() {
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    let prev = tmp.path().join("prev");
    expect_code(&run(&rank_args(&set, &wm, &prev)), 0);
    let before = tree_bytes(&prev);
    // A latent scale of 1e-38 blows the encoded frames up and the U-Net overflows.
    let blown = tmp.path().join("models").join("blown");
    copy_dir(&wm, &blown);
    let mut cfg = read_json(&blown.join("config.json"));
    cfg["model"]["latents"]["std"][0] = serde_json::json!(1e-38);
    std::fs::write(blown.join("config.json"), cfg.to_string()).unwrap();
    // D10: exit 2, the world model named once, not a failure of each policy.
    let mut args = rank_args(&set, &blown, &prev);
    args.push("--force");
    let (stdout, err) = expect_code(&run(&args), 2);
    assert!(err.contains("world model") && err.contains("blown"), "{err}");
    assert_eq!(err.matches("non-finite latents").count(), 1, "{err}");
    assert!(!stdout.contains("Pearson"), "{stdout}");
    // The failed --force run put the previous run back as it was.
    assert_eq!(tree_bytes(&prev), before);
    assert!(!tmp.path().join("prev.replaced").exists());
    // D17: a run that fails before writing a row leaves no folder behind.
    let fresh = tmp.path().join("fresh");
    expect_code(&run(&rank_args(&set, &blown, &fresh)), 2);
    assert!(!fresh.exists(), "a failed run left {}", fresh.display());
    let missing = tmp.path().join("no_model");
    expect_code(&run(&rank_args(&set, &missing, &fresh)), 2);
    assert!(!fresh.exists());
}

#[test]
fn resume_keeps_whole_batches_and_refuses_what_it_cannot_check() {
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    let out = tmp.path().join("run");
    let args = rank_args(&set, &wm, &out);
    expect_code(&run(&args), 0);
    let jsonl = out.join("episodes.jsonl");
    let rows = std::fs::read_to_string(&jsonl).unwrap();
    assert_eq!(rows.lines().count(), 2 * 4 * 2);
    let (csv, res) = (std::fs::read(out.join("episodes.csv")).unwrap(), results(&out));
    let mut again = args.clone();
    again.push("--resume");
    // D5: a complete last row without its newline used to get the next row glued on.
    std::fs::write(&jsonl, rows.trim_end()).unwrap();
    expect_code(&run(&again), 0);
    assert_eq!(std::fs::read_to_string(&jsonl).unwrap(), rows);
    // A torn last row (cut mid-way) is dropped; its batch runs again whole.
    std::fs::write(&jsonl, &rows[..rows.len() - 20]).unwrap();
    expect_code(&run(&again), 0);
    // D5: deleting a row used to re-run that seed alone (another batch shape, other
    // rounding) and keep its stale partner: 31 rows for 16 episodes. Now the batch
    // runs again whole, and the rows, csv and results equal the straight run's.
    let mut lines: Vec<&str> = rows.lines().collect();
    lines.remove(1);
    std::fs::write(&jsonl, lines.join("\n") + "\n").unwrap();
    let (_, err) = expect_code(&run(&again), 0);
    assert!(err.contains("dropped 3 rows of incomplete batches"), "{err}");
    let now = std::fs::read_to_string(&jsonl).unwrap();
    assert_eq!(now.lines().count(), 16);
    let (mut a, mut b): (Vec<&str>, Vec<&str>) = (now.lines().collect(), rows.lines().collect());
    a.sort_unstable();
    b.sort_unstable();
    assert_eq!(a, b);
    assert_eq!(std::fs::read(out.join("episodes.csv")).unwrap(), csv);
    assert_eq!(results(&out), res);
    // D11: new weights under a checkpoint's name cannot extend the run.
    let pj = set.join("noise100-lag0/policy.json");
    let original = std::fs::read_to_string(&pj).unwrap();
    let mut p = read_json(&pj);
    p["config"]["noise"] = serde_json::json!(150.0);
    std::fs::write(&pj, p.to_string()).unwrap();
    let (_, err) = expect_code(&run(&with_flag(&again, "--episodes", "6")), 2);
    assert!(err.contains("content of policy noise100-lag0 changed"), "{err}");
    std::fs::write(&pj, original).unwrap();
    // D6: rows without the settings they were run with cannot be resumed.
    std::fs::remove_file(out.join("config.json")).unwrap();
    let (_, err) = expect_code(&run(&with_flag(&again, "--max-steps", "7")), 2);
    assert!(err.contains("no config.json"), "{err}");
    assert_eq!(std::fs::read_to_string(&jsonl).unwrap(), now);
}

#[test]
fn gates_refuse_bad_thresholds_and_a_ranking_of_one_is_not_perfect() {
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    let out = tmp.path().join("run");
    let args = rank_args(&set, &wm, &out);
    // D8: NaN (which compares false) and values no correlation takes are refused.
    for bad in ["NaN", "2", "-1.5", "inf"] {
        let (_, err) = expect_code(&run(&[&args[..], &["--min-pearson", bad]].concat()), 2);
        assert!(err.contains("--min-pearson") && err.contains("[-1, 1]"), "{bad}: {err}");
    }
    assert!(!out.exists());
    // D9 and D18: one policy has no ranking: metrics null, exit 1, values printed plainly.
    let one = set.join("noise000-lag0");
    let single =
        [&rank_args(&one, &wm, &out)[..], &["--min-pearson", "0.5", "--max-inversions", "0"]].concat();
    let (stdout, err) = expect_code(&run(&single), 1);
    let ag = &read_json(&out.join("results.json"))["agreement"];
    for key in ["pearson", "rank_inversions", "rank_inversion_fraction", "mmrv", "regret_at_1"] {
        assert!(ag[key].is_null(), "{key}: {ag}");
    }
    assert!(
        err.contains("only 1 policies were ranked") && err.contains("Pearson is undefined (n/a)"),
        "{err}"
    );
    assert!(!err.contains("Some(") && !err.contains("None"), "{err}");
    assert!(stdout.contains("inversions n/a"), "{stdout}");
}

#[test]
fn seed_ranges_never_wrap_and_huge_counts_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("o");
    let max = u64::MAX.to_string();
    // D4: u64::MAX and then 0 (a training seed) used to run silently.
    for cmd in [&["simulate"][..], &["collect"][..], &["rank"][..]] {
        let args = [cmd, &["--seed-start", &max, "--episodes", "2", "--out", s(&out)][..]].concat();
        let (_, err) = expect_code(&run(&args), 2);
        assert!(err.contains("wrap around"), "{cmd:?}: {err}");
        assert!(!out.exists());
    }
    // D13: counts that would exhaust memory are refused before allocating.
    let (_, err) = expect_code(&run(&["rank", "--episodes", "100000000000", "--out", s(&out)]), 2);
    assert!(err.contains("--episodes 100000000000 is more than"), "{err}");
    let csv = tmp.path().join("s.csv");
    std::fs::write(&csv, "policy,predicted,actual\na,0.1,0.2\nb,0.3,0.4\n").unwrap();
    let (_, err) = expect_code(&run(&["agreement", "--csv", s(&csv), "--bootstrap", "1000000000"]), 2);
    assert!(err.contains("give 1 to 1000000"), "{err}");
    // D12: a closed stdout (`| head -1`) exits quietly instead of panicking.
    let mut child = evalharness()
        .args(["agreement", "--csv", s(&csv), "--bootstrap", "200"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let done = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&done.stderr);
    assert_eq!(done.status.code(), Some(0), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn damaged_datasets_scenarios_and_results_are_refused_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    // D3: a missing chunk used to read as zeros (score 0.000, SSIM 0.66).
    let data = tmp.path().join("d.zarr");
    expect_code(&run(&["collect", "--episodes", "2", "--max-steps", "5", "--out", s(&data)]), 0);
    expect_code(&run(&["dataset", "info", s(&data)]), 0);
    std::fs::remove_file(data.join("data/coverage/0")).unwrap();
    let (_, err) = expect_code(&run(&["dataset", "info", s(&data)]), 2);
    assert!(err.contains("data/coverage") && err.contains("chunk '0' is missing"), "{err}");
    // D14 and D15: scenarios that cannot run are refused at load, naming the field.
    let far = scenario_variant(
        tmp.path(),
        "far.toml",
        "min_agent_block_distance = 90.0",
        "min_agent_block_distance = 9000.0",
    );
    let zero = scenario_variant(tmp.path(), "zero.toml", "physics_hz = 100", "physics_hz = 0");
    let sim = tmp.path().join("sim");
    for (file, field) in [(&far, "reset.min_agent_block_distance"), (&zero, "physics_hz (0)")] {
        let args = ["simulate", "--scenario", s(file), "--episodes", "1", "--out", s(&sim)];
        let (_, err) = expect_code(&run(&args), 2);
        assert!(err.contains(field), "{err}");
    }
    // D16: `report` on a damaged results.json names the field.
    let (set, wm) = inputs(tmp.path());
    let out = tmp.path().join("run");
    let mut args = rank_args(&set, &wm, &out);
    args.retain(|a| *a != "--no-report");
    expect_code(&run(&args), 0);
    let path = out.join("results.json");
    let good = std::fs::read_to_string(&path).unwrap();
    let mut r: serde_json::Value = serde_json::from_str(&good).unwrap();
    r["policies"][1]["sim"]["mean"] = serde_json::json!("high");
    std::fs::write(&path, r.to_string()).unwrap();
    let (_, err) = expect_code(&run(&["report", s(&out)]), 2);
    assert!(err.contains("policies[1].sim.mean: invalid type: string \"high\", expected f64"), "{err}");
    r = serde_json::from_str(&good).unwrap();
    r.as_object_mut().unwrap().remove("agreement");
    std::fs::write(&path, r.to_string()).unwrap();
    let (_, err) = expect_code(&run(&["report", s(&out)]), 2);
    assert!(err.contains("missing field `agreement`"), "{err}");
    // The earlier layouts (version 2 without `scoring`, version 1 without `schema_version`
    // either) are reported; a later one is refused by name.
    r = serde_json::from_str(&good).unwrap();
    assert_eq!(r["schema_version"], 4);
    assert_eq!(r["scoring"], "max over the episode of clip(coverage / 0.95, 0, 1)");
    // Version 3 kept Push-T's scene checks as fields of their own: read into `scene`, and the
    // report states them as it does this build's.
    let html_now = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html_now.contains("goal kept: MuJoCo"), "the report states the scene checks");
    r["schema_version"] = serde_json::json!(3);
    for p in r["policies"].as_array_mut().unwrap() {
        for branch in ["sim", "world_model"] {
            let b = p[branch].as_object_mut().unwrap();
            let scene = b.remove("scene").unwrap();
            for (k, v) in scene.as_object().unwrap() {
                b.insert(k.clone(), v.clone());
            }
        }
    }
    std::fs::write(&path, r.to_string()).unwrap();
    expect_code(&run(&["report", s(&out)]), 0);
    let html_v3 = std::fs::read_to_string(out.join("report.html")).unwrap();
    let scene_sentence = |h: &str| h.find("Scene kept").map(|i| h[i..].chars().take(400).collect::<String>());
    assert_eq!(scene_sentence(&html_v3), scene_sentence(&html_now));
    r.as_object_mut().unwrap().remove("scoring");
    r["schema_version"] = serde_json::json!(2);
    std::fs::write(&path, r.to_string()).unwrap();
    expect_code(&run(&["report", s(&out)]), 0);
    r.as_object_mut().unwrap().remove("schema_version");
    std::fs::write(&path, r.to_string()).unwrap();
    expect_code(&run(&["report", s(&out)]), 0);
    r["schema_version"] = serde_json::json!(5);
    std::fs::write(&path, r.to_string()).unwrap();
    let (_, err) = expect_code(&run(&["report", s(&out)]), 2);
    assert!(err.contains("results schema version 5, written by a later evalharness"), "{err}");
    // A damaged filmstrip index, or a missing PNG, is reported and marked in the page.
    std::fs::write(&path, &good).unwrap();
    let index = out.join("filmstrips/index.json");
    let listed = read_json(&index);
    let png = out.join("filmstrips").join(listed[0]["png"].as_str().unwrap());
    std::fs::remove_file(&png).unwrap();
    let (_, err) = expect_code(&run(&["report", s(&out)]), 0);
    assert!(err.contains("is missing"), "{err}");
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("Filmstrips:") && html.contains("is missing"));
    std::fs::write(&index, b"[{\"png\": ").unwrap();
    let (_, err) = expect_code(&run(&["report", s(&out)]), 0);
    assert!(err.contains("index.json") && err.contains("none shown"), "{err}");
}
