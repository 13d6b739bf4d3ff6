//! The Can pipeline on tiny settings, as a user runs it: collect, every model
//! trained on the data, `collect --policy` for post-training rollouts, `rank
//! --scenario can` with the models, and the table of tasks over the run.

use crate::util::{TinyArm, expect_code, read_json, run, s, tiny_arm_models};

#[test]
fn the_can_pipeline_collects_trains_every_model_and_ranks() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // 10 episodes of 12 steps: nothing reaches the target bin that fast.
    let TinyArm { data, wm, judge, pol, judge_stdout, .. } = tiny_arm_models(dir, "can");
    let attrs = read_json(&data.join(".zattrs"));
    assert_eq!(attrs["evalharness"]["scenario"], "can", "{attrs}");
    assert!(judge_stdout.contains("(0 above 0.5)"), "{judge_stdout}");
    // The world model reads Can's 7-D OSC_POSE actions.
    assert_eq!(read_json(&wm.join("config.json"))["model"]["unet"]["action_dim"], 7);

    // Rollouts of the checkpoints, run on past the step limit's successes, in Can's layout.
    let col = dir.join("rollouts.zarr");
    let args = ["collect", "--scenario", "can", "--policy", s(&pol), "--episodes", "1", "--max-steps", "3"];
    let more = ["--no-early-stop", "--out", s(&col)];
    let (stdout, _) = expect_code(&run(&[&args[..], &more[..]].concat()), 0);
    assert!(stdout.contains("can dataset: 2 episodes of 2 checkpoint(s), 6 steps"), "{stdout}");
    let attrs = read_json(&col.join(".zattrs"));
    assert_eq!(attrs["evalharness"]["no_early_stop"], true, "{attrs}");

    // The open-loop success check on rollouts long enough for a 64-frame video: each
    // checkpoint's episode replayed in the world model, read by the judge, grouped by
    // checkpoint against the dataset's exact success.
    let long = dir.join("rollouts-long.zarr");
    let args = ["collect", "--scenario", "can", "--policy", s(&pol), "--episodes", "1", "--max-steps", "66"];
    expect_code(&run(&[&args[..], &["--no-early-stop", "--out", s(&long)]].concat()), 0);
    let ev = dir.join("eval");
    let args =
        ["wm", "eval", "--world-model", s(&wm), "--data", s(&long), "--all-episodes", "--judge", s(&judge)];
    let few = ["--episodes", "1", "--full-episodes"];
    let code = run(&[&args[..], &few[..], &["0", "--out", s(&ev)]].concat());
    let (_, stderr) = expect_code(&code, 2);
    assert!(stderr.contains("--judge reads whole-episode videos"), "{stderr}");
    let (stdout, _) = expect_code(&run(&[&args[..], &few[..], &["2", "--out", s(&ev)]].concat()), 0);
    assert!(stdout.contains("open-loop success, by behaviour"), "{stdout}");
    let eval = read_json(&ev.join("eval.json"));
    let row = &eval["open_loop_success"][0];
    let episodes = read_json(&long.join(".zattrs"))["evalharness"]["episodes"].clone();
    let groups = row["groups"].as_array().cloned().unwrap_or_default();
    assert_eq!(groups.len(), 2, "{row}");
    for (g, ep) in groups.iter().zip(episodes.as_array().into_iter().flatten()) {
        assert_eq!(g["group"], ep["behaviour"], "{row}");
        assert_eq!(g["episodes"], 1, "{row}");
        let exact = if ep["success"] == true { 1.0 } else { 0.0 };
        assert_eq!(g["exact"].as_f64(), Some(exact), "{row} {ep}");
        for key in ["judged_real", "imagined"] {
            assert!([Some(0.0), Some(1.0)].contains(&g[key].as_f64()), "{row}");
        }
    }
    assert_eq!(row["all"]["episodes"], 2, "{row}");

    // MuJoCo with the policy seeing its frames through the world model's autoencoder:
    // scored exactly, and the run says what the policy saw.
    let obs = dir.join("observed");
    let args = ["simulate", "--scenario", "can", "--policy", s(&pol), "--episodes", "1", "--max-steps", "4"];
    let (stdout, _) = expect_code(
        &run(&[&args[..], &["--observe-through", s(&wm), "--seed", "7", "--out", s(&obs)]].concat()),
        0,
    );
    assert_eq!(stdout.matches("success 0.0%").count(), 2, "{stdout}");
    let summary = read_json(&obs.join("summary.json"));
    assert_eq!(summary["observe_through"], s(&wm), "{summary}");
    assert_eq!(summary["seed"], 7, "the policies' noise seed is recorded: {summary}");
    let o2 = dir.join("o2");
    let refused = [&args[..], &["--observe-through", s(&wm), "--record-scores", "--out", s(&o2)]];
    let (_, stderr) = expect_code(&run(&refused.concat()), 2);
    assert!(stderr.contains("cannot be given with --observe-through"), "{stderr}");
    let builtin = ["simulate", "--scenario", "can", "--policy", "expert", "--observe-through", s(&wm)];
    let (_, stderr) = expect_code(&run(&[&builtin[..], &["--out", s(&dir.join("o3"))]].concat()), 2);
    assert!(stderr.contains("is a built-in behaviour"), "{stderr}");

    // The imagined episodes' actions replayed in MuJoCo: in 4 steps nothing reaches the
    // bin in MuJoCo, whether the policy acts or its imagined actions are replayed, so
    // every imagined success (if any) is one whose actions fail there.
    let rep = dir.join("replay");
    let args = ["simulate", "--scenario", "can", "--policy", s(&pol), "--episodes", "2", "--max-steps", "4"];
    let recorded = dir.join("replays.zarr");
    let more =
        ["--replay-imagined", s(&wm), "--judge", s(&judge), "--record", s(&recorded), "--out", s(&rep)];
    let (stdout, _) = expect_code(&run(&[&args[..], &more[..]].concat()), 0);
    assert!(stdout.contains("imagined actions in MuJoCo 0.00"), "{stdout}");
    // The replays as a dataset: one episode per replayed row, labelled with its
    // checkpoint, its length the row's, with the imagined outcome beside the real one.
    assert!(stdout.contains("can dataset: 4 replayed episodes"), "{stdout}");
    let attrs = read_json(&recorded.join(".zattrs"))["evalharness"].clone();
    assert_eq!((attrs["scenario"].as_str(), attrs["replay_imagined"].as_str()), (Some("can"), Some(s(&wm))));
    let rows: Vec<serde_json::Value> = std::fs::read_to_string(rep.join("replay.jsonl"))
        .unwrap_or_default()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let eps = attrs["episodes"].as_array().cloned().unwrap_or_default();
    assert_eq!(eps.len(), rows.len(), "{attrs}");
    for (e, r) in eps.iter().zip(&rows) {
        let label = format!("{}/imagined-actions", r["policy"].as_str().unwrap_or("?"));
        assert_eq!(
            (e["seed"].clone(), e["steps"].clone()),
            (r["seed"].clone(), r["steps"].clone()),
            "{e} {r}"
        );
        assert_eq!(
            (e["behaviour"].as_str(), e["success"].as_bool()),
            (Some(label.as_str()), Some(false)),
            "{e}"
        );
        assert!(e["imagined_success"].is_boolean(), "{e}");
    }
    // They merge with the scripted data, as post-training data does.
    let merged = dir.join("merged.zarr");
    expect_code(&run(&["dataset", "merge", s(&data), s(&recorded), "--out", s(&merged)]), 0);
    // A second run refuses to overwrite the dataset.
    let rep2 = dir.join("rep2");
    let again = ["--replay-imagined", s(&wm), "--record", s(&recorded), "--out", s(&rep2)];
    let (_, stderr) = expect_code(&run(&[&args[..], &again[..]].concat()), 2);
    assert!(stderr.contains("replays.zarr"), "{stderr}");
    let replay = read_json(&rep.join("replay.json"));
    for p in replay["policies"].as_array().into_iter().flatten() {
        assert_eq!(
            (p["episodes"].as_u64(), p["mujoco"].as_f64(), p["imagined_success_holds"].as_u64()),
            (Some(2), Some(0.0), Some(0)),
            "{p}"
        );
        let imagined = p["imagined"].as_f64().unwrap_or(-1.0);
        assert_eq!(p["imagined_success_fails"].as_f64(), Some(2.0 * imagined), "{p}");
    }
    let lines = std::fs::read_to_string(rep.join("replay.jsonl")).unwrap_or_default();
    assert_eq!(lines.lines().count(), 4, "2 policies × 2 replayed episodes: {lines}");
    // Two workers (one checkpoint each) write the same files as one.
    let rep_j2 = dir.join("replay-j2");
    let more = ["--replay-imagined", s(&wm), "--judge", s(&judge), "--jobs", "2", "--out", s(&rep_j2)];
    expect_code(&run(&[&args[..], &more[..]].concat()), 0);
    for f in ["episodes.jsonl", "replay.jsonl"] {
        let read = |d: &std::path::Path| std::fs::read_to_string(d.join(f)).unwrap_or_default();
        assert_eq!(read(&rep_j2), read(&rep), "{f} with --jobs 2");
    }
    assert_eq!(replay["seed"], 0, "rank's default noise seed: {replay}");
    // Without --judge, away from the repository's checkpoints/can/judge: refused before
    // anything runs, naming where the judge was looked for.
    let elsewhere = ["--replay-imagined", s(&wm), "--out", s(&rep2)];
    let code = crate::util::evalharness()
        .current_dir(dir)
        .args([&args[..], &elsewhere[..]].concat())
        .output()
        .expect("evalharness runs");
    let (_, stderr) = expect_code(&code, 2);
    assert!(stderr.contains("checkpoints/can/judge is not a folder here"), "{stderr}");
    assert!(!rep2.exists());
    let builtin = ["simulate", "--scenario", "can", "--policy", "expert", "--replay-imagined", s(&wm)];
    let (_, stderr) = expect_code(&run(&[&builtin[..], &["--out", s(&dir.join("r2"))]].concat()), 2);
    assert!(stderr.contains("only a policy checkpoint acts on imagined frames"), "{stderr}");
    let r3 = dir.join("r3");
    let seeded = ["simulate", "--scenario", "can", "--policy", "expert", "--seed", "3", "--out", s(&r3)];
    let (_, stderr) = expect_code(&run(&seeded), 2);
    assert!(stderr.contains("--seed 3: it seeds a policy checkpoint's sampling noise"), "{stderr}");

    // rank both epochs in both branches: 2 policies × 2 episodes of 4 steps.
    let out = dir.join("rank");
    let args = ["rank", "--scenario", "can", "--world-model", s(&wm), "--judge", s(&judge)];
    let more = ["--episodes", "2", "--max-steps", "4", "--no-report", "--policies", s(&pol)];
    let (stdout, _) = expect_code(&run(&[&args[..], &more[..], &["--out", s(&out)]].concat()), 0);
    assert!(stdout.contains("MuJoCo success"), "{stdout}");
    // `simulate --replay-imagined` ran the same episodes (seeds, judge, noise seed, batch):
    // its MuJoCo and imagined rows are rank's, line for line.
    let sorted = |p: std::path::PathBuf| {
        let mut v: Vec<String> =
            std::fs::read_to_string(p).unwrap_or_default().lines().map(String::from).collect();
        v.sort();
        v
    };
    let ranked = sorted(out.join("episodes.jsonl"));
    assert_eq!(ranked.len(), 8, "2 policies × 2 seeds × 2 branches");
    assert_eq!(sorted(rep.join("episodes.jsonl")), ranked);
    let res = read_json(&out.join("results.json"));
    assert_eq!(res["policies"].as_array().map(Vec::len), Some(2), "{res}");
    assert_eq!(res["failed_policies"].as_array().map(Vec::len), Some(0), "{res}");
    // Nothing reaches the target bin in 4 MuJoCo steps; the imagined branch, read by the
    // judge, gives a rate over both episodes.
    for p in res["policies"].as_array().into_iter().flatten() {
        assert_eq!(p["sim"]["success_rate"].as_f64(), Some(0.0), "{p}");
        let imagined = p["world_model"]["success_rate"].as_f64().unwrap_or(-1.0);
        assert!([0.0, 0.5, 1.0].contains(&imagined), "{p}");
        // Seed by seed: with no MuJoCo success, each imagined success is an imagined-only
        // seed (2 episodes × the imagined rate) and the other seeds fail in both.
        let paired = &p["paired_success"];
        let count = |k: &str| paired[k].as_f64().unwrap_or(-1.0);
        assert_eq!((count("both"), count("sim_only")), (0.0, 0.0), "{p}");
        assert_eq!((count("imagined_only"), count("neither")), (2.0 * imagined, 2.0 - 2.0 * imagined), "{p}");
    }
    assert!(stdout.contains("imagined only"), "{stdout}");
    // No MuJoCo episode succeeds, so every resampled MuJoCo run reads 0 for both policies:
    // the noise ceiling's Pearson is undefined, with no inversion and no error.
    let ceiling = &res["agreement"]["noise_ceiling"];
    assert!(ceiling["pearson"].is_null(), "{ceiling}");
    assert_eq!(
        (ceiling["rank_inversions"].as_f64(), ceiling["mean_abs_error"].as_f64()),
        (Some(0.0), Some(0.0))
    );
    assert!(
        stdout.contains("noise ceiling (two resampled MuJoCo runs of this size agree at): Pearson n/a"),
        "{stdout}"
    );
    assert_eq!(res["scenario"], "can", "{res}");
    // The world model sampled at temperature 0: recorded in the run's resolved config
    // (absent from the default run's); a scale outside [0, 1] is refused, naming the flag,
    // and so is one in a model folder's config.json, naming the file.
    let cold = dir.join("rank-cold");
    let one = ["--episodes", "1", "--max-steps", "4", "--no-report", "--policies", s(&pol)];
    expect_code(&run(&[&args[..], &one[..], &["--noise-scale", "0", "--out", s(&cold)]].concat()), 0);
    assert_eq!(read_json(&cold.join("config.json"))["world_model_config"]["noise_scale"], 0.0);
    let plain = read_json(&out.join("config.json"));
    assert!(plain["world_model_config"].get("noise_scale").is_none(), "{plain}");
    let hot_out = dir.join("rank-hot");
    let hot = ["--noise-scale", "1.5", "--out", s(&hot_out)];
    let (_, stderr) = expect_code(&run(&[&args[..], &one[..], &hot[..]].concat()), 2);
    assert!(
        stderr.contains("--noise-scale: the noise scale must be a finite value in [0, 1], got 1.5"),
        "{stderr}"
    );
    let wm_hot = dir.join("wm-hot");
    std::fs::create_dir(&wm_hot).unwrap();
    std::fs::copy(wm.join("ema.bpk"), wm_hot.join("ema.bpk")).unwrap();
    let mut cfg = read_json(&wm.join("config.json"));
    cfg["model"]["noise_scale"] = serde_json::json!(2.0);
    std::fs::write(wm_hot.join("config.json"), cfg.to_string()).unwrap();
    let args_hot = ["rank", "--scenario", "can", "--world-model", s(&wm_hot), "--judge", s(&judge)];
    let (_, stderr) =
        expect_code(&run(&[&args_hot[..], &one[..], &["--out", s(&dir.join("rank-hot2"))]].concat()), 2);
    assert!(stderr.contains("wm-hot/config.json") && stderr.contains("\"noise_scale\""), "{stderr}");
    // The table of tasks reads the run: Can, 2 policies × 2 episodes from seed 100000.
    let (md, _) = expect_code(&run(&["tasks", s(&out)]), 0);
    assert!(md.contains("| can | 2 × 2 |") && md.contains("| 100000–100001 |"), "{md}");
}
