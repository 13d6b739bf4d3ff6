//! `simulate` and `collect` on robomimic Lift and Can: the experts succeed, outputs are
//! byte-identical for any `--jobs`, and bad input is refused by name; `rank`'s
//! filmstrips show the run's own episodes.

use std::path::Path;

use crate::util::{evalharness, expect_code, read_json, run, s, tree_bytes};

fn simulate(out: &std::path::Path, policy: &str, jobs: &str) -> std::process::Output {
    run(&[
        "simulate",
        "--scenario",
        "lift",
        "--policy",
        policy,
        "--episodes",
        "3",
        "--seed-start",
        "40",
        "--max-steps",
        "70",
        "--gif-size",
        "32",
        "--jobs",
        jobs,
        "--out",
        out.to_str().unwrap(),
    ])
}

#[test]
fn the_expert_lifts_and_any_jobs_gives_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let (one, two) = (dir.path().join("one"), dir.path().join("two"));
    let (stdout, _) = expect_code(&simulate(&one, "expert", "1"), 0);
    assert!(stdout.contains("lift expert: 3 episodes, success rate 100.0%"), "{stdout}");
    expect_code(&simulate(&two, "expert", "2"), 0);
    assert_eq!(tree_bytes(&one), tree_bytes(&two), "--jobs 1 and --jobs 2 differ");
    let s = read_json(&one.join("summary.json"));
    let per = s["per_episode"].as_array().unwrap();
    assert_eq!(per.iter().map(|e| e["seed"].as_u64().unwrap()).collect::<Vec<_>>(), [40, 41, 42]);
    // Episodes end at the first success: the last line of each is the lifting step.
    let lines = std::fs::read_to_string(one.join("episodes.jsonl")).unwrap();
    let rows: Vec<serde_json::Value> = lines.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let steps: u64 = per.iter().map(|e| e["steps"].as_u64().unwrap()).sum();
    assert_eq!(rows.len() as u64, steps);
    let first = &rows[0];
    assert_eq!(first["state"].as_array().unwrap().len(), 23);
    assert_eq!(first["action"].as_array().unwrap().len(), 7);
    let ends: Vec<&serde_json::Value> =
        rows.windows(2).filter(|w| w[0]["seed"] != w[1]["seed"]).map(|w| &w[0]).collect();
    for end in ends.into_iter().chain([&rows[rows.len() - 1]]) {
        assert_eq!(end["success"], true, "{end}");
    }
    // The cube's centre starts 0.01 m above the 0.8 m table plus its half height
    // (0.020 to 0.022 m): between 0.830 and 0.832.
    let z = first["state"][2].as_f64().unwrap();
    assert!((0.830..=0.832).contains(&z), "{z}");
    assert!(one.join("episode_40.gif").is_file());
    assert_eq!(std::fs::read_to_string(one.join("initial_states.jsonl")).unwrap().lines().count(), 3);
}

/// `--renderer mujoco` draws MuJoCo's frames beside a task's own renderer; Lift's frames are
/// MuJoCo's, and the flag was once silently ignored there.
#[test]
fn a_second_renderer_is_refused_where_the_task_has_none() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r");
    let args =
        ["simulate", "--scenario", "lift", "--renderer", "mujoco", "--episodes", "1", "--out", s(&out)];
    let (_, stderr) = expect_code(&run(&args), 2);
    assert!(stderr.contains("--renderer mujoco: the lift task's frames are MuJoCo's already"), "{stderr}");
    assert!(!out.exists());
}

#[test]
fn a_missed_grasp_never_lifts() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("miss");
    let (stdout, _) = expect_code(&simulate(&out, "miss", "2"), 0);
    assert!(stdout.contains("success rate 0.0%"), "{stdout}");
}

#[test]
fn collect_writes_a_lift_dataset_identical_for_any_jobs() {
    let dir = tempfile::tempdir().unwrap();
    let make = |name: &str, jobs: &str| {
        let out = dir.path().join(name);
        let args = [
            "collect",
            "--scenario",
            "lift",
            "--episodes",
            "3",
            "--seed-start",
            "7",
            "--max-steps",
            "12",
            "--jobs",
            jobs,
            "--out",
        ];
        let mut a: Vec<&str> = args.to_vec();
        let o = out.to_str().unwrap().to_string();
        a.push(&o);
        expect_code(&run(&a), 0);
        out
    };
    let (one, two) = (make("a.zarr", "1"), make("b.zarr", "2"));
    assert_eq!(tree_bytes(&one), tree_bytes(&two), "--jobs 1 and --jobs 2 differ");
    let res = run(&["dataset", "info", one.to_str().unwrap(), "--json"]);
    let (stdout, _) = expect_code(&res, 0);
    let info: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    // 3 episodes of 12 steps: no behaviour lifts the cube in 12 steps (the
    // expert needs about 50), so every episode scores 0, read from data/success.
    assert_eq!(info["steps"], 36, "{info}");
    assert_eq!(info["state_dim"], 23);
    assert_eq!(info["action_dim"], 7);
    assert_eq!(info["image"], serde_json::json!([96, 96, 3]));
    assert_eq!(info["score_source"], "data/success");
    assert_eq!(info["score"]["success_rate"], 0.0);
    let attrs = read_json(&one.join(".zattrs"));
    assert_eq!(attrs["evalharness"]["scenario"], "lift");
    assert_eq!(attrs["evalharness"]["state_columns"].as_array().unwrap().len(), 23);
}

#[test]
fn collect_no_early_stop_keeps_the_episode_going_after_success() {
    let dir = tempfile::tempdir().unwrap();
    let collect = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let args =
            ["collect", "--scenario", "lift", "--mix", "expert=1", "--episodes", "1", "--max-steps", "80"];
        expect_code(&run(&[&args[..], extra, &["--out", s(&out)]].concat()), 0);
        let (stdout, _) = expect_code(&run(&["dataset", "info", s(&out), "--json"]), 0);
        serde_json::from_str::<serde_json::Value>(&stdout).unwrap()
    };
    // The expert lifts the cube in about 55 steps: the episode ends there by default,
    // and runs to the 80-step limit with the flag, still a success.
    let stopped = collect("stop.zarr", &[]);
    let steps = stopped["steps"].as_u64().unwrap();
    assert!((40..80).contains(&steps), "{stopped}");
    let kept = collect("kept.zarr", &["--no-early-stop"]);
    assert_eq!(kept["steps"], 80, "{kept}");
    assert_eq!(kept["score"]["success_rate"], 1.0, "{kept}");
    // Push-T episodes have no such switch.
    let res = run(&["collect", "--no-early-stop", "--episodes", "1", "--out", s(&dir.path().join("p"))]);
    let (_, stderr) = expect_code(&res, 2);
    assert!(stderr.contains("--no-early-stop: pusht episodes end at success"), "{stderr}");
}

#[test]
fn collect_policy_no_early_stop_keeps_a_policys_episode_going_after_success() {
    let dir = tempfile::tempdir().unwrap();
    let policy = Path::new(env!("CARGO_MANIFEST_DIR")).join("checkpoints/lift/policies/epoch-0060");
    let collect = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let args = ["collect", "--scenario", "lift", "--policy", s(&policy), "--episodes", "1"];
        let seeds = ["--seed-start", "2000000", "--max-steps", "80"];
        expect_code(&run(&[&args[..], &seeds, extra, &["--out", s(&out)]].concat()), 0);
        let (stdout, _) = expect_code(&run(&["dataset", "info", s(&out), "--json"]), 0);
        let attrs = read_json(&out.join(".zattrs"));
        (serde_json::from_str::<serde_json::Value>(&stdout).unwrap(), attrs)
    };
    // The shipped epoch 60 lifts the cube in about 57 steps: by default its episode ends with
    // the action chunk that lifted it; with the flag it runs to the 80-step limit, a success.
    let (stopped, attrs) = collect("stop.zarr", &[]);
    let steps = stopped["steps"].as_u64().unwrap();
    assert!((40..80).contains(&steps), "{stopped}");
    assert_eq!(stopped["score"]["success_rate"], 1.0, "{stopped}");
    assert_eq!(attrs["evalharness"]["no_early_stop"], false, "{attrs}");
    let (kept, attrs) = collect("kept.zarr", &["--no-early-stop"]);
    assert_eq!(kept["steps"], 80, "{kept}");
    assert_eq!(kept["score"]["success_rate"], 1.0, "{kept}");
    assert_eq!(attrs["evalharness"]["no_early_stop"], true, "{attrs}");
    // Push-T has no such switch, with a policy either.
    let pusht = Path::new(env!("CARGO_MANIFEST_DIR")).join("checkpoints/pusht/policies/epoch-0001");
    let args = ["collect", "--policy", s(&pusht), "--no-early-stop", "--episodes", "1"];
    let (_, stderr) = expect_code(&run(&[&args[..], &["--out", s(&dir.path().join("p"))]].concat()), 2);
    assert!(stderr.contains("--no-early-stop: pusht episodes end at success"), "{stderr}");
}

#[test]
fn bad_lift_input_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x");
    let o = out.to_str().unwrap();
    // An unknown key in a Lift scenario file.
    let toml = dir.path().join("lift.toml");
    std::fs::write(&toml, "name = \"lift\"\ncube_sise = 0.02\n").unwrap();
    let res = run(&["simulate", "--scenario", toml.to_str().unwrap(), "--episodes", "1", "--out", o]);
    let (_, stderr) = expect_code(&res, 2);
    assert!(stderr.contains("cube_sise"), "{stderr}");
    // Missing assets name the fix.
    let res = evalharness()
        .env("EVALHARNESS_ROBOSUITE_ASSETS", dir.path().join("nowhere"))
        .args(["simulate", "--scenario", "lift", "--episodes", "1", "--out", o])
        .output()
        .unwrap();
    let (_, stderr) = expect_code(&res, 2);
    assert!(stderr.contains("scripts/setup.sh"), "{stderr}");
    // A zero step limit would write empty episodes, a negative or NaN noise nonsense: both
    // are refused at parsing, naming the flag, for every scenario command.
    for cmd in ["simulate", "collect"] {
        let res = run(&[cmd, "--scenario", "lift", "--episodes", "1", "--max-steps", "0", "--out", o]);
        let (_, stderr) = expect_code(&res, 2);
        assert!(stderr.contains("invalid value '0' for '--max-steps"), "{stderr}");
        for noise in ["--noise=-0.1", "--noise=NaN"] {
            let res = run(&[cmd, "--scenario", "lift", noise, "--out", o]);
            let (_, stderr) = expect_code(&res, 2);
            assert!(stderr.contains("'--noise") && stderr.contains("finite std >= 0"), "{stderr}");
        }
    }
    // An unknown behaviour lists the built-in ones.
    let res = run(&["simulate", "--scenario", "lift", "--policy", "teleop", "--out", o]);
    let (_, stderr) = expect_code(&res, 2);
    assert!(stderr.contains("expert, miss, drop, push, hesitate, random"), "{stderr}");
    // Regression: a checkpoint folder that does not exist (yet) was called an unknown
    // behaviour; it is named as a missing folder.
    let missing = dir.path().join("run/epoch-0020");
    let res = run(&["simulate", "--scenario", "can", "--policy", s(&missing), "--out", o]);
    let (_, stderr) = expect_code(&res, 2);
    assert!(
        stderr.contains(&format!("--policy {}: no such checkpoint folder", missing.display())),
        "{stderr}"
    );
    // rank names every missing input at once (here the policies and the world model; a
    // missing judge is named too, as the rank defaults' unit test checks).
    let nowhere = dir.path().join("no_world_model");
    let res = run(&["rank", "--scenario", "lift", "--policies", o, "--world-model", s(&nowhere), "--out", o]);
    let (_, stderr) = expect_code(&res, 2);
    assert!(stderr.contains("missing inputs:") && stderr.contains("policies: "), "{stderr}");
    assert!(stderr.contains("world model: ") && stderr.contains("no_world_model"), "{stderr}");
    assert!(!out.exists(), "nothing written on refusal");
}

#[test]
fn the_can_expert_places_the_can_and_any_jobs_gives_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let sim = |name: &str, jobs: &str| {
        let out = dir.path().join(name);
        let res = run(&[
            "simulate",
            "--scenario",
            "can",
            "--episodes",
            "2",
            "--seed-start",
            "60",
            "--max-steps",
            "220",
            "--gif-size",
            "32",
            "--jobs",
            jobs,
            "--out",
            out.to_str().unwrap(),
        ]);
        (out, res)
    };
    let (one, res) = sim("one", "1");
    let (stdout, _) = expect_code(&res, 0);
    assert!(stdout.contains("can expert: 2 episodes, success rate 100.0%"), "{stdout}");
    let (two, res) = sim("two", "2");
    expect_code(&res, 0);
    assert_eq!(tree_bytes(&one), tree_bytes(&two), "--jobs 1 and --jobs 2 differ");
    let lines = std::fs::read_to_string(one.join("episodes.jsonl")).unwrap();
    let last: serde_json::Value = serde_json::from_str(lines.lines().last().unwrap()).unwrap();
    assert_eq!(last["success"], true);
    // The can starts in bin 1 (y around −0.25) and its state row starts with its position.
    let first: serde_json::Value = serde_json::from_str(lines.lines().next().unwrap()).unwrap();
    let y = first["state"][1].as_f64().unwrap();
    assert!((-0.41..=-0.09).contains(&y), "{y}");
    // rank needs a world model of Can; without one it names the missing input (the shipped
    // Can judge is found).
    let nowhere = dir.path().join("no_world_model");
    let args = ["rank", "--scenario", "can", "--policies", s(&one), "--world-model", s(&nowhere)];
    let res = run(&[&args[..], &["--out", "unused"]].concat());
    let (_, stderr) = expect_code(&res, 2);
    assert!(stderr.contains("world model: ") && stderr.contains("no_world_model"), "{stderr}");
    assert!(!stderr.contains("judge: "), "{stderr}");
}

#[test]
fn collect_writes_a_can_dataset_with_its_default_mix() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("can.zarr");
    let o = out.to_str().unwrap();
    let res = run(&[
        "collect",
        "--scenario",
        "can",
        "--episodes",
        "4",
        "--seed-start",
        "3",
        "--max-steps",
        "6",
        "--out",
        o,
    ]);
    let (stdout, _) = expect_code(&res, 0);
    assert!(stdout.contains("can dataset: 4 episodes, 24 steps"), "{stdout}");
    let attrs = read_json(&out.join(".zattrs"));
    let e = &attrs["evalharness"];
    assert_eq!(e["scenario"], "can");
    // Half expert, the other half spread over the six flawed behaviours: 0.5 / 6 each
    // (`explore` is opt-in: adding it once changed this default, and this caught it).
    let sixth = 0.5 / 6.0;
    let want = format!(
        "expert=0.5,miss={sixth},drop={sixth},wrong-bin={sixth},push={sixth},hesitate={sixth},random={sixth}"
    );
    assert_eq!(e["mix"], want.as_str());
    assert_eq!(e["state_columns"][0], "can_x");
    // An unknown behaviour in the mix names the task's behaviours.
    let bad = dir.path().join("bad.zarr");
    let res = run(&["collect", "--scenario", "can", "--mix", "teleop=1", "--out", bad.to_str().unwrap()]);
    let (_, stderr) = expect_code(&res, 2);
    assert!(stderr.contains("unknown can behaviour 'teleop'"), "{stderr}");
    assert!(!bad.exists());
}

#[test]
fn rank_filmstrips_show_the_runs_own_episodes_when_resumed_or_sharded_too() {
    // A run takes its filmstrips from the frames it recorded. A resumed run finds those of
    // its earlier process in `filmstrip-frames/`, the run joining `--processes` shards those
    // of the shards; a run without them (resuming a finished one) replays. On Lift an
    // episode's frames depend on the episodes beside it in its batch (these 4 seeds end at
    // different steps, and replaying the two picked seeds alone drew another worst
    // episode), so a replay runs the picked episode's whole batch and gives the same bytes.
    let tmp = tempfile::tempdir().unwrap();
    let (first, resumed, split) =
        (tmp.path().join("run"), tmp.path().join("resumed"), tmp.path().join("split"));
    let pol = Path::new(env!("CARGO_MANIFEST_DIR")).join("checkpoints/lift/policies/epoch-0014");
    let args = ["rank", "--scenario", "lift", "--policies", s(&pol), "--episodes", "4", "--bootstrap", "10"];
    let more = ["--max-steps", "150", "--batch", "4"];
    // One policy ranks nothing against another: exit 1, the run and its report complete.
    let (_, err) = expect_code(&run(&[&args[..], &more[..], &["--out", s(&first)]].concat()), 1);
    assert!(!err.contains("replaying"), "{err}");
    assert!(!first.join("filmstrip-frames").exists(), "the kept frames are removed");
    // The run records Lift's parameters as it loaded them, its default rendering (no
    // multisampling, no reflections) among them, and their fingerprint, which a resume compares.
    let cfg = read_json(&first.join("config.json"));
    let visual = &cfg["scenario_parameters"]["visual"];
    assert_eq!(
        (visual["samples"].as_u64(), visual["reflections"].as_bool()),
        (Some(0), Some(false)),
        "{cfg}"
    );
    assert!(cfg["fingerprints"]["scenario parameters"].as_str().is_some_and(|f| f.starts_with("sha256:")));
    crate::util::copy_dir(&first, &resumed);
    std::fs::remove_dir_all(resumed.join("filmstrips")).unwrap();
    let (_, err) =
        expect_code(&run(&[&args[..], &more[..], &["--out", s(&resumed), "--resume"]].concat()), 1);
    assert!(err.contains("replaying epoch-0014's batch of 4 episodes"), "{err}");
    let strips = tree_bytes(&first.join("filmstrips"));
    assert_eq!(strips.len(), 5, "best and worst, PNG and GIF, and the index");
    assert_eq!(strips, tree_bytes(&resumed.join("filmstrips")));
    // Two shard processes of two batches each keep their frames for the joining run.
    let split_args = ["--max-steps", "40", "--batch", "2", "--processes", "2", "--out", s(&split)];
    let (_, err) = expect_code(&run(&[&args[..], &split_args[..]].concat()), 1);
    assert!(!err.contains("replaying"), "{err}");
    assert_eq!(tree_bytes(&split.join("filmstrips")).len(), 5);
    assert!(!split.join("filmstrip-frames").exists());
}
