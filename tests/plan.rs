//! `plan` (GPC-RANK) on the pipeline's tiny models: three planners on the same
//! seeds, files and statistics, thread-count independence, and bad input.

use std::path::Path;

use crate::util::{expect_code, read_json, run, s, scenario_variant, with_flag};

/// Runs `plan` with the tiny world model `wm` (and a goal-free one, `gf`) proposing
/// with the checkpoint `policy`; called by the pipeline test, which built them.
pub fn check(dir: &Path, wm: &Path, gf: &Path, policy: &Path) {
    let out = dir.join("plan");
    let base = [
        "plan",
        "--policy",
        s(policy),
        "--world-model",
        s(wm),
        "--episodes",
        "3",
        "--max-steps",
        "10",
        "--proposals",
        "3",
        "--batch",
        "2",
        "--bootstrap",
        "50",
    ];
    let mut args = base.to_vec();
    args.extend(["--out", s(&out), "--jobs", "2"]);
    let (stdout, _) = expect_code(&run(&args), 0);
    assert!(stdout.contains("vs none") && stdout.contains("a pick at random"), "{stdout}");
    let res = read_json(&out.join("results.json"));
    let cfg = read_json(&out.join("config.json"));
    // The tiny policy predicts 16 actions from 2 observations: 15 lie ahead, all imagined;
    // it executes its own action horizon.
    assert_eq!(cfg["imagine"], 15, "{cfg}");
    let execute = cfg["execute"].as_u64().unwrap();
    for p in ["none", "world-model", "simulator"] {
        let v = &res["planners"][p];
        assert_eq!(v["episodes"], 3, "{p}: {v}");
        let mean = v["mean"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&mean), "{p}: {v}");
        // 10 steps in chunks of `execute`, per episode (none of these succeeds).
        assert_eq!(v["decisions"].as_u64().unwrap(), 3 * 10u64.div_ceil(execute), "{p}: {v}");
    }
    // `none` executes the first proposal, so it is never replaced; the others are compared to it.
    assert_eq!(res["planners"]["none"]["replaced_fraction"], 0.0);
    assert!(res["planners"]["none"].get("vs_none").is_none());
    for p in ["world-model", "simulator"] {
        let d = &res["planners"][p]["vs_none"];
        let (better, worse) = (d["episodes_better"].as_u64().unwrap(), d["episodes_worse"].as_u64().unwrap());
        assert!(better + worse <= 3, "{d}");
    }
    let vs = &res["planners"]["world-model"]["vs_simulator"];
    let agree = vs["pick_agreement"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&agree) && vs["mean_regret_units"].as_f64().unwrap() >= 0.0, "{vs}");
    assert!(vs["random_pick_mean_regret_units"].as_f64().unwrap() >= 0.0, "{vs}");
    // The first two seeds' decisions are drawn (real frames over each imagination's outcome).
    for f in ["none_seed100050.png", "world-model_seed100051.png", "simulator_seed100050.png"] {
        assert!(out.join("filmstrips").join(f).is_file(), "missing {f}");
    }
    let rows = std::fs::read_to_string(out.join("episodes.jsonl")).unwrap();
    assert_eq!(rows.lines().count(), 3 * 3); // planners x seeds
    let csv = std::fs::read_to_string(out.join("episodes.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 9);

    // One thread gives the same rows.
    let out1 = dir.join("plan1");
    let mut args1 = base.to_vec();
    args1.extend(["--out", s(&out1), "--jobs", "1"]);
    expect_code(&run(&args1), 0);
    assert_eq!(std::fs::read_to_string(out1.join("episodes.csv")).unwrap(), csv);

    // --resume redoes nothing; a 2-episode run grown to 3 equals the straight run; other
    // settings are refused, naming them.
    let mut again = args.clone();
    again.push("--resume");
    expect_code(&run(&again), 0);
    assert_eq!(std::fs::read_to_string(out.join("episodes.csv")).unwrap(), csv);
    let grown = dir.join("plan_grown");
    let mut short = with_flag(&base, "--episodes", "2");
    short.extend(["--out", s(&grown)]);
    expect_code(&run(&short), 0);
    let mut grow = with_flag(&short, "--episodes", "3");
    grow.push("--resume");
    expect_code(&run(&grow), 0);
    assert_eq!(std::fs::read_to_string(grown.join("episodes.csv")).unwrap(), csv);
    let (_, err) = expect_code(&run(&with_flag(&again, "--proposals", "2")), 2);
    assert!(err.contains("proposals (saved: 3, now: 2)"), "{err}");

    // A goal-free world model plans too (the goal is drawn onto its frames before scoring).
    let out_gf = dir.join("plan_gf");
    let mut a = with_flag(&base, "--world-model", s(gf));
    a.extend(["--out", s(&out_gf), "--planners", "world-model"]);
    expect_code(&run(&a), 0);
    let r = read_json(&out_gf.join("results.json"));
    assert_eq!(r["planners"].as_object().unwrap().len(), 1, "{r}");

    // With a margin no proposal can beat, the simulator planner keeps the policy's own.
    let out_m = dir.join("plan_margin");
    let mut a = base.to_vec();
    a.extend(["--out", s(&out_m), "--planners", "simulator", "--margin", "1e9", "--record", "0"]);
    expect_code(&run(&a), 0);
    let r = read_json(&out_m.join("results.json"));
    assert_eq!(r["planners"]["simulator"]["replaced_fraction"], 0.0, "{r}");
    assert!(!out_m.join("filmstrips").exists());

    // Bad input: an existing output, more actions than the policy predicts, a policy
    // kind without sampling noise, a missing world model.
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("already exists"), "{err}");
    let bad = [dir.join("plan_bad"), dir.join("plan_bad2"), dir.join("plan_bad3"), dir.join("plan_bad4")];
    let mut a = base.to_vec();
    a.extend(["--out", s(&bad[0]), "--imagine", "16"]);
    let (_, err) = expect_code(&run(&a), 2);
    assert!(err.contains("--imagine 16") && err.contains("predicts 15 actions"), "{err}");
    let scripted = Path::new(env!("CARGO_MANIFEST_DIR")).join("checkpoints/pusht/scripted/noise000-lag0");
    let mut a = with_flag(&base, "--policy", s(&scripted));
    a.extend(["--out", s(&bad[1])]);
    let (_, err) = expect_code(&run(&a), 2);
    assert!(err.contains("noise000-lag0") && err.contains("kind \"scripted\""), "{err}");
    // A scenario rendering 64x64 frames: the 96x96 policy is refused, naming both sizes
    // (only the planners without a world model run, so the policy is what is checked).
    let small = scenario_variant(dir, "small.toml", "size = 96 ", "size = 64 ");
    let mut a = base.to_vec();
    a.extend(["--out", s(&bad[3]), "--scenario", s(&small), "--planners", "none"]);
    let (_, err) = expect_code(&run(&a), 2);
    assert!(err.contains("takes 96x96 frames, the scenario renders 64x64"), "{err}");
    let missing = dir.join("no_wm");
    let mut a = with_flag(&base, "--world-model", s(&missing));
    a.extend(["--out", s(&bad[2])]);
    let (_, err) = expect_code(&run(&a), 2);
    assert!(err.contains("no_wm"), "{err}");
}
