//! `evalharness simulate`: outputs, determinism, bad input.

use crate::util::{expect_code, read_json, run, scenario_variant};

#[test]
fn expert_episodes_write_summary_steps_and_gif() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim");
    let o = out.to_str().unwrap();
    let res = run(&[
        "simulate",
        "--policy",
        "expert",
        "--episodes",
        "2",
        "--seed-start",
        "3",
        "--max-steps",
        "40",
        "--gif-size",
        "64",
        "--out",
        o,
    ]);
    let (stdout, _) = expect_code(&res, 0);
    assert!(stdout.contains("2 episodes"), "{stdout}");
    let s = read_json(&out.join("summary.json"));
    assert_eq!(s["episodes"], 2);
    let per = s["per_episode"].as_array().unwrap();
    assert_eq!(per[0]["seed"], 3);
    assert_eq!(per[1]["seed"], 4);
    let steps: u64 = per.iter().map(|e| e["steps"].as_u64().unwrap()).sum();
    let mean = per.iter().map(|e| e["score"].as_f64().unwrap()).sum::<f64>() / 2.0;
    assert!((s["mean_score"].as_f64().unwrap() - mean).abs() < 1e-12);
    // One JSON line per control step, with the documented keys.
    let lines = std::fs::read_to_string(out.join("episodes.jsonl")).unwrap();
    assert_eq!(lines.lines().count() as u64, steps);
    let first: serde_json::Value = serde_json::from_str(lines.lines().next().unwrap()).unwrap();
    for key in ["seed", "step", "agent", "block", "goal", "action", "coverage"] {
        assert!(first.get(key).is_some(), "missing {key} in {first}");
    }
    assert_eq!(first["block"].as_array().unwrap().len(), 3);
    let gif = std::fs::read(out.join("episode_3.gif")).unwrap();
    assert_eq!(&gif[..6], b"GIF89a");
    let config = read_json(&out.join("config.json"));
    assert_eq!(config["scenario"], "pusht");
    assert_eq!(config["scenario_config"]["name"], "pusht");
    assert!(!dir.path().join("sim.partial").exists());
}

#[test]
fn existing_output_needs_force() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("sim");
    std::fs::create_dir(&o).unwrap();
    let o = o.to_str().unwrap();
    let args = ["simulate", "--policy", "explore", "--episodes", "1", "--max-steps", "5", "--out", o];
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("already exists") && err.contains("--force"), "{err}");
    let mut forced = args.to_vec();
    forced.push("--force");
    expect_code(&run(&forced), 0);
}

#[test]
fn unknown_scenario_and_policy_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("x");
    let o = o.to_str().unwrap();
    let (_, err) = expect_code(&run(&["simulate", "--scenario", "pushq", "--out", o]), 2);
    assert!(err.contains("unknown scenario 'pushq'") && err.contains("pusht"), "{err}");
    let (_, err) = expect_code(&run(&["simulate", "--policy", "oracle", "--out", o]), 2);
    assert!(
        err.contains(
            "unknown pusht behaviour 'oracle' (built-in: expert, explore, decoy; or a checkpoint folder)"
        ),
        "{err}"
    );
}

#[test]
fn scenario_file_errors_name_file_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let bad = scenario_variant(dir.path(), "bad.toml", "[task]", "[task]\nmax_stpes = 3");
    let o = dir.path().join("x");
    let args = ["simulate", "--scenario", bad.to_str().unwrap(), "--out", o.to_str().unwrap()];
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("bad.toml") && err.contains("max_stpes"), "{err}");
    assert!(!o.exists());
}

#[test]
fn diverging_simulation_names_seed_and_step() {
    // A PD gain far beyond the explicit integrator's stability limit (kp dt^2 >> 1)
    // makes the agent's motion explode within a few steps.
    let dir = tempfile::tempdir().unwrap();
    let unstable = scenario_variant(dir.path(), "unstable.toml", "kp = 100.0", "kp = 1.0e9");
    let o = dir.path().join("x");
    let args = [
        "simulate",
        "--scenario",
        unstable.to_str().unwrap(),
        "--policy",
        "explore",
        "--seed-start",
        "11",
        "--episodes",
        "1",
        "--out",
        o.to_str().unwrap(),
    ];
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("seed 11") && err.contains("step"), "{err}");
    assert!(!o.exists(), "no complete-looking output after an error");
}

#[test]
fn scripted_policies_act_from_frames_and_grade_with_noise() {
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("scripted");
    let s = set.to_str().unwrap();
    let (stdout, _) = expect_code(&run(&["scripted", "--out", s, "--noise", "0,200", "--lag", "0"]), 0);
    assert_eq!(stdout.lines().count(), 2, "{stdout}");
    let file = read_json(&set.join("noise200-lag0/policy.json"));
    assert_eq!(file["kind"], "scripted");
    assert_eq!(file["config"]["noise"], 200.0);
    // Writing over it needs --force.
    expect_code(&run(&["scripted", "--out", s, "--noise", "0"]), 2);

    let out = dir.path().join("sim");
    let o = out.to_str().unwrap();
    let args =
        ["simulate", "--policy", s, "--episodes", "2", "--seed-start", "3", "--max-steps", "80", "--out", o];
    expect_code(&run(&args), 0);
    let summary = read_json(&out.join("summary.json"));
    let mean = |i: usize| summary["policies"][i]["mujoco"]["mean"].as_f64().unwrap();
    assert_eq!(summary["policies"][0]["name"], "noise000-lag0");
    // The noiseless expert, reading block and goal from the frames, pushes the T most of
    // the way in 80 steps; with σ = 200 units of action noise it barely gets anywhere.
    assert!(mean(0) > 0.5 && mean(0) > mean(1) + 0.2, "{} vs {}", mean(0), mean(1));

    // A config that leaves no action is named with its file.
    std::fs::write(
        set.join("noise200-lag0/policy.json"),
        r#"{"kind": "scripted", "config": {"noise": 0, "lag": 8, "action_horizon": 8}}"#,
    )
    .unwrap();
    let args = ["simulate", "--policy", s, "--episodes", "1", "--max-steps", "8", "--out", o, "--force"];
    expect_code(&run(&args), 1);
    let summary = read_json(&out.join("summary.json"));
    let err = summary["policies"][1]["error"].as_str().unwrap();
    assert!(
        err.contains("noise200-lag0/policy.json") && err.contains("'config.lag': 8 must be below"),
        "{err}"
    );
}
