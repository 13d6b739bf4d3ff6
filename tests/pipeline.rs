//! The whole pipeline on tiny inputs: dataset → autoencoder → world model →
//! policy → `wm eval`, `simulate --policy`, `rank` (resume, jobs, a corrupt
//! checkpoint among good ones, gates), `plan`.

use std::path::{Path, PathBuf};

use crate::util::{expect_code, old_row_layout, read_json, run, s, with_flag, without_timing};

/// Builds dataset, autoencoder, world model and one policy checkpoint in `dir`.
fn build(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    let data = dir.join("data.zarr");
    // 10 explorer episodes of 68 steps: episode 9 is held out and long enough for
    // a 64-frame evaluation (4 context + 60 generated).
    let args = [
        "collect",
        "--episodes",
        "10",
        "--seed-start",
        "0",
        "--max-steps",
        "68",
        "--mix",
        "explore=1",
        "--out",
        s(&data),
    ];
    expect_code(&run(&args), 0);
    let ae = dir.join("autoencoder");
    expect_code(
        &run(&["train", "autoencoder", "--data", s(&data), "--out", s(&ae), "--steps", "1", "--batch", "2"]),
        0,
    );
    let wm = dir.join("wm");
    let (stdout, _) = expect_code(
        &run(&[
            "train",
            "world-model",
            "--data",
            s(&data),
            "--autoencoder",
            s(&ae),
            "--out",
            s(&wm),
            "--steps",
            "2",
            "--base-channels",
            "16",
            "--contexts",
            "2",
            "--samples",
            "2",
            "--eval-every",
            "1",
            // The anchor path end to end: training, `rank`'s world-model branch, replays.
            "--anchor",
        ]),
        0,
    );
    assert!(stdout.contains("step 2/2"), "{stdout}");
    let prov = read_json(&wm.join("provenance.json"));
    assert!(prov["metrics"]["held_out_one_chunk_latent_mse"].as_f64().unwrap().is_finite());
    assert_eq!(read_json(&wm.join("config.json"))["model"]["autoencoder"], "../autoencoder");
    let pol = dir.join("policies");
    let (stdout, _) = expect_code(
        &run(&[
            "train",
            "policy",
            "--data",
            s(&data),
            "--out",
            s(&pol),
            "--epochs",
            "1",
            "--episodes",
            "1",
            "--behaviour",
            "all",
            "--batch",
            "34",
            "--encoder-width",
            "8",
            "--down-dims",
            "16,32",
            "--inference-steps",
            "2",
            "--encoder-steps",
            "3",
        ]),
        0,
    );
    assert!(stdout.contains("saved") && stdout.contains("epoch-0001"), "{stdout}");
    // The encoder was pose-pre-trained for 3 steps, then frozen.
    let prov = read_json(&pol.join("epoch-0001/policy.json"));
    assert_eq!(prov["provenance"]["encoder_pretraining"]["steps"], 3, "{prov}");
    (data, wm, pol)
}

#[test]
fn pipeline_end_to_end() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (data, wm, pol) = build(dir);

    // wm eval: one held-out 64-frame video; metrics and a filmstrip.
    let ev = dir.join("eval");
    let args = [
        "wm",
        "eval",
        "--world-model",
        s(&wm),
        "--data",
        s(&data),
        "--episodes",
        "1",
        "--full-episodes",
        "1",
        "--out",
        s(&ev),
    ];
    expect_code(&run(&args), 0);
    let e = read_json(&ev.join("eval.json"));
    // The model's two rows, then the references on the same videos: persistence, and the
    // model's autoencoder round-tripping the real future frames.
    assert_eq!(e["models"].as_array().unwrap().len(), 6);
    assert_eq!(e["models"][0]["frames"], 60);
    assert_eq!(e["models"][1]["frames"], 64); // the whole 68-step episode after 4 context frames
    for (row, name, frames) in [(2, "persistence", 60), (3, "persistence", 64), (4, "wm:autoencoder", 60)] {
        assert_eq!(e["models"][row]["name"], name);
        assert_eq!(e["models"][row]["frames"], frames);
    }
    assert_eq!(e["models"][5]["objective"], "round-trip");
    let ssim = e["models"][0]["ssim"].as_f64().unwrap();
    assert!((-1.0..=1.0).contains(&ssim), "{ssim}");
    assert!(ev.join("filmstrip.png").is_file());
    // The open-loop score check: the model's and persistence's rows score the same real
    // frames, and that score matches the coverage `collect` recorded for them (held-out
    // episode 9, frames 4.. after its context; observation j shows the state after
    // action j − 1) within the frame scorer's error.
    let scores = e["open_loop_scores"].as_array().unwrap();
    assert_eq!(
        scores.iter().map(|r| r["name"].as_str().unwrap()).collect::<Vec<_>>(),
        ["wm", "persistence"] // the model is the folder `wm`
    );
    let reader = harness::replay::ReplayReader::open(&data).unwrap();
    let ep = reader.episode_range(9);
    let cov = reader.read_episode(9, &["coverage".to_string()]).unwrap().extras[0].clone();
    let recorded =
        cov[3..ep.len() - 1].iter().map(|&c| (f64::from(c) / 0.95).clamp(0.0, 1.0)).fold(0.0, f64::max);
    for r in scores {
        let real = r["real_mean"].as_f64().unwrap();
        assert!((real - recorded).abs() < 0.06, "real {real} vs recorded {recorded}");
        assert_eq!(r["real_mean"], scores[0]["real_mean"]);
        assert!((0.0..=1.0).contains(&r["imagined_mean"].as_f64().unwrap()), "{r}");
        // One 64-frame video: no correlation; coverage at frames 0, 8, 16 and 32.
        assert!(r["pearson"].is_null(), "{r}");
        let frames: Vec<u64> =
            r["coverage_curve"].as_array().unwrap().iter().map(|p| p["frame"].as_u64().unwrap()).collect();
        assert_eq!(frames, [0, 8, 16, 32], "{r}");
    }
    assert_eq!(e["episodes_64"], serde_json::json!([9]));
    assert_eq!(e["episodes_whole"], serde_json::json!([9]));
    // --all-episodes (a dataset no model was trained on) takes episodes from the start.
    let all = [&args[..6], &["--episodes", "2", "--full-episodes", "0", "--all-episodes"]].concat();
    let ev_all = dir.join("eval_all");
    expect_code(&run(&[&all[..], &["--out", s(&ev_all)]].concat()), 0);
    let e = read_json(&ev_all.join("eval.json"));
    assert_eq!(e["episodes_64"], serde_json::json!([0, 1]));
    assert_eq!(e["models"][0]["videos"], 2, "{e}");

    // A policy set: the trained checkpoint, a copy, and a corrupt one.
    let set = dir.join("set");
    std::fs::create_dir_all(&set).unwrap();
    for name in ["a", "b", "c"] {
        let d = set.join(name);
        std::fs::create_dir_all(&d).unwrap();
        for f in ["policy.json", "model.bpk"] {
            std::fs::copy(pol.join("epoch-0001").join(f), d.join(f)).unwrap();
        }
    }
    std::fs::write(set.join("c/model.bpk"), b"truncated").unwrap();

    // simulate --policy scores each checkpoint; the corrupt one is reported, the others kept.
    let sim = dir.join("sim");
    let args = [
        "simulate",
        "--policy",
        s(&set),
        "--episodes",
        "2",
        "--max-steps",
        "9",
        "--record-scores",
        "--out",
        s(&sim),
    ];
    let (stdout, _) = expect_code(&run(&args), 1);
    assert!(stdout.contains("mean score"), "{stdout}");
    let summary = read_json(&sim.join("summary.json"));
    assert!(summary["policies"][2]["error"].as_str().unwrap().contains("model.bpk"));
    let prov = read_json(&set.join("a/provenance.json"));
    assert!(prov["mujoco_score"]["mean"].as_f64().is_some());

    // rank: exit 1 because policy c failed; a and b (identical weights, different names
    // and therefore different noise) are both ranked.
    let out = dir.join("rank");
    let base = [
        "rank",
        "--policies",
        s(&set),
        "--world-model",
        s(&wm),
        "--episodes",
        "3",
        "--max-steps",
        "10",
        "--batch",
        "2",
        "--bootstrap",
        "50",
    ];
    let mut args = base.to_vec();
    args.extend(["--out", s(&out), "--jobs", "2"]);
    let (stdout, _) = expect_code(&run(&args), 1);
    assert!(stdout.contains("Pearson"), "{stdout}");
    let res = read_json(&out.join("results.json"));
    assert_eq!(res["policies"].as_array().unwrap().len(), 2);
    assert_eq!(res["failed_policies"][0]["policy"], "c");
    for key in ["pearson", "spearman", "kendall_tau_b", "rank_inversions", "mmrv", "regret_at_1", "ci95"] {
        assert!(res["agreement"].get(key).is_some(), "missing agreement.{key}");
    }
    assert_eq!(res["policies"][0]["sim"]["episodes"], 3);
    // Every row records how much of the block its last seen frame shows: the whole T
    // (its rendered area is ~1.06 of the polygon's) in MuJoCo, whatever the tiny world
    // model kept in imagination; the run prints the imagined mean.
    for p in res["policies"].as_array().unwrap() {
        let sim = p["sim"]["scene"]["block_area"].as_f64().unwrap();
        assert!((0.8..1.1).contains(&sim), "MuJoCo block area {sim}");
        assert!(p["world_model"]["scene"]["block_area"].as_f64().unwrap().is_finite());
        let goal = p["sim"]["scene"]["goal_kept"].as_f64().unwrap();
        assert!((0.85..=1.0).contains(&goal), "MuJoCo goal kept {goal}");
        assert!(p["world_model"]["scene"]["goal_kept"].as_f64().unwrap().is_finite());
        // The agent is drawn over everything: all of its disk shows in MuJoCo.
        let agent = p["sim"]["scene"]["agent_kept"].as_f64().unwrap();
        assert!((0.8..=1.0).contains(&agent), "MuJoCo agent kept {agent}");
        assert!(p["world_model"]["scene"]["agent_kept"].as_f64().unwrap().is_finite());
    }
    assert!(stdout.contains("block area") && stdout.contains("agent kept"), "{stdout}");
    let rows = std::fs::read_to_string(out.join("episodes.jsonl")).unwrap();
    assert_eq!(rows.lines().count(), 2 * 3 * 2); // policies x seeds x branches
    // The parquet table holds the same rows, typed.
    let table = reports::episodes::read_episodes_parquet(&out.join("episodes.parquet")).unwrap();
    assert_eq!(table.len(), 12);
    let parquet = std::fs::read(out.join("episodes.parquet")).unwrap();

    // --resume redoes nothing: the rows stay exactly the same.
    let mut again = args.clone();
    again.push("--resume");
    expect_code(&run(&again), 1);
    assert_eq!(std::fs::read_to_string(out.join("episodes.jsonl")).unwrap(), rows);
    // A run written before rows named their task's fields (Push-T's `final_block`, `goal`,
    // `block_area`, `goal_kept`, `agent_kept` and `max_coverage` as fields of their own)
    // resumes: its rows are read into the named maps, and the results are the same.
    std::fs::write(out.join("episodes.jsonl"), rows.lines().map(old_row_layout).collect::<String>()).unwrap();
    expect_code(&run(&again), 1);
    assert_eq!(read_json(&out.join("results.json"))["policies"], res["policies"]);
    std::fs::write(out.join("episodes.jsonl"), &rows).unwrap();
    // Resuming under other settings would mix rows of two experiments: refused, and the
    // finished rows stay.
    let (_, err) = expect_code(&run(&with_flag(&again, "--max-steps", "7")), 2);
    assert!(err.contains("--resume") && err.contains("max_steps (saved: "), "{err}");
    // So is another batch size: the kernels' rounding depends on it.
    let (_, err) = expect_code(&run(&with_flag(&again, "--batch", "3")), 2);
    assert!(err.contains("batch (saved: 2, now: 3)"), "{err}");
    assert_eq!(std::fs::read_to_string(out.join("episodes.jsonl")).unwrap(), rows);
    // More episodes extend a run that ends on a whole batch: 2 episodes at --batch 2,
    // grown to 3, give exactly the straight 3-episode run (seeds 0-1 and 2 are its two
    // batches). Fewer episodes, or growing a run that ends in a part batch, are refused.
    let (_, err) = expect_code(&run(&with_flag(&again, "--episodes", "2")), 2);
    assert!(err.contains("--episodes 2 would drop"), "{err}");
    let (_, err) = expect_code(&run(&with_flag(&again, "--episodes", "5")), 2);
    assert!(err.contains("part batch"), "{err}");
    let grown = dir.join("rank_grown");
    let mut short = with_flag(&base, "--episodes", "2");
    short.extend(["--out", s(&grown), "--no-report"]);
    expect_code(&run(&short), 1);
    assert_eq!(std::fs::read_to_string(grown.join("episodes.jsonl")).unwrap().lines().count(), 2 * 2 * 2);
    let mut grow = with_flag(&short, "--episodes", "3");
    grow.push("--resume");
    expect_code(&run(&grow), 1);
    assert_eq!(std::fs::read(grown.join("episodes.parquet")).unwrap(), parquet);
    assert_eq!(without_timing(read_json(&grown.join("results.json"))), without_timing(res.clone()));

    // One thread gives the same rows and results (timings aside).
    let out1 = dir.join("rank1");
    let mut args1 = base.to_vec();
    args1.extend(["--out", s(&out1), "--jobs", "1"]);
    expect_code(&run(&args1), 1);
    assert_eq!(std::fs::read_to_string(out1.join("episodes.jsonl")).unwrap(), rows);
    assert_eq!(std::fs::read(out1.join("episodes.parquet")).unwrap(), parquet);
    assert_eq!(without_timing(read_json(&out1.join("results.json"))), without_timing(res));

    // Two shards merged give exactly the unsharded rows and results (timings aside).
    let mut shard_dirs = Vec::new();
    for i in 0..2 {
        let d = dir.join(format!("shard{i}"));
        let mut a = base.to_vec();
        let spec = format!("{i}/2");
        a.extend(["--out", s(&d), "--shard", &spec, "--no-report"]);
        expect_code(&run(&a), 1);
        shard_dirs.push(d);
    }
    let merged = dir.join("merged");
    let args = ["merge", s(&shard_dirs[0]), s(&shard_dirs[1]), "--out", s(&merged), "--no-report"];
    expect_code(&run(&args), 0);
    assert_eq!(std::fs::read_to_string(merged.join("episodes.jsonl")).unwrap(), rows);
    assert_eq!(std::fs::read(merged.join("episodes.parquet")).unwrap(), parquet);
    assert_eq!(
        without_timing(read_json(&merged.join("results.json"))),
        without_timing(read_json(&out1.join("results.json")))
    );

    // With a shared claims folder a shard runs the batches it claims first: one after
    // the other, the first takes all four and the second none, and the join is the same.
    let claims = dir.join("claims");
    let mut claimed = Vec::new();
    for i in 0..2 {
        let d = dir.join(format!("claimed{i}"));
        let mut a = base.to_vec();
        let spec = format!("{i}/2");
        a.extend(["--out", s(&d), "--shard", &spec, "--claims", s(&claims), "--no-report"]);
        expect_code(&run(&a), 1); // the corrupt checkpoint fails in each
        claimed.push(d);
    }
    // (A shard that ran nothing has no rows file.)
    let lines =
        |d: &Path| std::fs::read_to_string(d.join("episodes.jsonl")).unwrap_or_default().lines().count();
    assert_eq!((lines(&claimed[0]), lines(&claimed[1])), (12, 0));
    assert_eq!(std::fs::read_dir(&claims).unwrap().count(), 4, "a claim per batch (2 policies x 2)");
    let joined = dir.join("joined");
    let args = ["merge", s(&claimed[0]), s(&claimed[1]), "--out", s(&joined), "--no-report"];
    expect_code(&run(&args), 0);
    assert_eq!(std::fs::read_to_string(joined.join("episodes.jsonl")).unwrap(), rows);

    // `--processes 2` runs those two shards as processes, joins them and finishes the run
    // (the corrupt checkpoint fails in its shard and is reported by the joined run: exit 1).
    let procs = dir.join("procs");
    let mut a = base.to_vec();
    a.extend(["--out", s(&procs), "--processes", "2", "--no-report"]);
    let (stdout, _) = expect_code(&run(&a), 1);
    assert_eq!(std::fs::read_to_string(procs.join("episodes.jsonl")).unwrap(), rows);
    assert_eq!(std::fs::read(procs.join("episodes.parquet")).unwrap(), parquet);
    let res_procs = without_timing(read_json(&procs.join("results.json")));
    assert_eq!(res_procs, without_timing(read_json(&out1.join("results.json"))));
    assert!(stdout.contains("Pearson") && !stdout.contains("merged"), "{stdout}");
    // Its timing is the whole command's wall clock and the shards' summed thread times.
    let t = &read_json(&procs.join("results.json"))["timing"];
    assert!(t["note"].as_str().unwrap().starts_with("2 shard processes at once"), "{t}");
    assert!(
        t["wall_seconds"].as_f64().unwrap() > 0.0 && t["world_model_seconds"].as_f64().unwrap() > 0.0,
        "{t}"
    );
    assert!(!dir.join("procs.shards").exists(), "the joined shards' folders are left");
    // `--resume` keeps an interrupted run's claims: shard 1 takes its own back, and the
    // batch held by a shard of another split (7) is run by the joined run; same rows.
    let resumed = dir.join("procs_resumed");
    let held = dir.join("procs_resumed.shards/claims");
    std::fs::create_dir_all(&held).unwrap();
    // The tool marks the shards' folder as its own (a user's folder of that name is refused).
    std::fs::write(dir.join("procs_resumed.shards/.evalharness-owned"), "shards\n").unwrap();
    std::fs::write(held.join("policy-0-batch-0"), "1").unwrap();
    std::fs::write(held.join("policy-1-batch-1"), "7").unwrap();
    let mut r = base.to_vec();
    r.extend(["--out", s(&resumed), "--processes", "2", "--no-report", "--resume"]);
    expect_code(&run(&r), 1);
    assert_eq!(std::fs::read_to_string(resumed.join("episodes.jsonl")).unwrap(), rows);
    assert!(!dir.join("procs_resumed.shards").exists());
    // It runs the shards itself, and replaces a run only when told to.
    let mut sharded = a.clone();
    sharded.extend(["--shard", "0/2"]);
    let (_, err) = expect_code(&run(&sharded), 2);
    assert!(err.contains("without --shard"), "{err}");
    let (_, err) = expect_code(&run(&a), 2);
    assert!(err.contains(&format!("--out {} exists", procs.display())), "{err}");
    assert_eq!(std::fs::read_to_string(procs.join("episodes.jsonl")).unwrap(), rows);
    // A shard that fails is named with the end of its log, and the run it would have
    // replaced stays (Push-T has no judge folder for --judge-persist to apply to).
    let mut bad = a.clone();
    bad.extend(["--force", "--judge-persist", "2"]);
    let (_, err) = expect_code(&run(&bad), 2);
    assert!(err.contains("--processes: shard ") && err.contains("no judge folder"), "{err}");
    assert_eq!(std::fs::read_to_string(procs.join("episodes.jsonl")).unwrap(), rows);

    // Without the corrupt checkpoint the run passes, unless a gate fails.
    std::fs::remove_dir_all(set.join("c")).unwrap();
    let out2 = dir.join("rank2");
    let mut ok = base.to_vec();
    ok.extend(["--out", s(&out2)]);
    expect_code(&run(&ok), 0);
    // The report: plots in PNG and SVG, LaTeX, CSV, filmstrips, one self-contained page.
    for f in [
        "plots/scatter.png",
        "plots/scatter.svg",
        "plots/bars.svg",
        "plots/bump.png",
        "table.tex",
        "summary.csv",
    ] {
        assert!(out2.join(f).is_file(), "missing {f}");
    }
    let index = read_json(&out2.join("filmstrips/index.json"));
    assert!(!index.as_array().unwrap().is_empty());
    let html = std::fs::read_to_string(out2.join("report.html")).unwrap();
    assert!(html.contains("data:image/png;base64,") && !html.contains("src=\"http"));
    screenshot(&out2.join("report.html"), &dir.join("report.png"));
    // `report` re-renders the same page from the files alone.
    std::fs::remove_file(out2.join("report.html")).unwrap();
    expect_code(&run(&["report", s(&out2)]), 0);
    assert_eq!(std::fs::read_to_string(out2.join("report.html")).unwrap(), html);
    // A gate above every correlation is refused as a setting; one at 1 fails unless the
    // two policies' scores lie on a rising line (their r is +1, -1 or undefined).
    let (_, err) = expect_code(&run(&[&ok[..], &["--force", "--min-pearson", "1.01"]].concat()), 2);
    assert!(err.contains("[-1, 1]"), "{err}");
    let r = read_json(&out2.join("results.json"))["agreement"]["pearson"].as_f64();
    ok.extend(["--force", "--max-inversions", "0", "--min-pearson", "1"]);
    if r == Some(1.0) {
        expect_code(&run(&ok), 0);
    } else {
        let (_, err) = expect_code(&run(&ok), 1);
        assert!(err.contains("gate failed: Pearson"), "{err}");
        assert!(!err.contains("Some("), "{err}");
    }

    // A goal-free world model: trained on the frames re-rendered without the goal (its
    // config and provenance say so), compared by `wm eval` with the others on the real
    // frames (the goal drawn back), and ranked with.
    let gf = dir.join("wm_goal_free");
    let ae = dir.join("autoencoder");
    let train = ["train", "world-model", "--data", s(&data), "--autoencoder", s(&ae), "--out", s(&gf)];
    let tiny = ["--steps", "1", "--base-channels", "16", "--contexts", "2", "--samples", "2", "--anchor"];
    expect_code(&run(&[&train[..], &tiny[..], &["--goal-free"]].concat()), 0);
    assert_eq!(read_json(&gf.join("config.json"))["model"]["goal_free"], true);
    let frames = read_json(&gf.join("provenance.json"))["frames"].as_str().unwrap().to_string();
    assert!(frames.contains("without the goal"), "{frames}");
    let ev = dir.join("eval_goal_free");
    let args = ["wm", "eval", "--world-model", s(&wm), "--world-model", s(&gf), "--data", s(&data)];
    let more = ["--episodes", "1", "--full-episodes", "1", "--out", s(&ev)];
    expect_code(&run(&[&args[..], &more[..]].concat()), 0);
    let e = read_json(&ev.join("eval.json"));
    let names: Vec<&str> =
        e["models"].as_array().unwrap().iter().map(|m| m["name"].as_str().unwrap()).collect();
    let refs = ["persistence", "persistence", "wm:autoencoder", "wm:autoencoder"];
    let refs = [&refs[..], &["wm_goal_free:autoencoder", "wm_goal_free:autoencoder"]].concat();
    assert_eq!(names, [&["wm", "wm", "wm_goal_free", "wm_goal_free"][..], &refs[..]].concat());
    let out3 = dir.join("rank_goal_free");
    let mut args = base.to_vec();
    args[4] = s(&gf);
    args.extend(["--out", s(&out3), "--no-report"]);
    expect_code(&run(&args), 0);
    assert_eq!(read_json(&out3.join("results.json"))["world_model"], s(&gf));
    // Resuming a goal-free run without the flag keeps it goal-free (its config wins).
    expect_code(&run(&[&train[..], &["--resume", "--steps", "2"]].concat()), 0);
    assert_eq!(read_json(&gf.join("config.json"))["model"]["goal_free"], true);

    // GPC-RANK planning with the same models.
    crate::plan::check(dir, &wm, &gf, &pol.join("epoch-0001"));
    // A learned judge of the same dataset, and a rank scored by it.
    crate::judge::check(dir, &data, &wm, &set);
}

#[test]
fn rank_reports_a_missing_world_model() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("r");
    let missing = tmp.path().join("nope");
    let args = ["rank", "--world-model", s(&missing), "--out", s(&out)];
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("world model: ") && err.contains("nope is not a folder"), "{err}");
    // A folder without a model names the file it lacks.
    std::fs::create_dir(&missing).unwrap();
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("nope") && err.contains("config.json"), "{err}");
    assert!(!out.exists(), "nothing written on refusal");
}

/// Screenshots a report with headless Chromium (Debian's `chromium`; `scripts/setup.sh
/// --tests` installs it) and checks that the page rendered: a non-trivial PNG.
pub fn screenshot(html: &Path, png: &Path) {
    let status = std::process::Command::new("chromium")
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--window-size=1280,1800"])
        .arg(format!("--screenshot={}", png.display()))
        .arg(format!("file://{}", html.display()))
        .output()
        .expect("chromium runs (scripts/setup.sh --tests installs it)");
    assert!(status.status.success(), "{}", String::from_utf8_lossy(&status.stderr));
    let bytes = std::fs::read(png).unwrap();
    assert!(bytes.starts_with(b"\x89PNG") && bytes.len() > 20_000, "screenshot is {} bytes", bytes.len());
}
