//! Helpers: run the binary in a scrubbed environment, read its outputs.

use std::path::Path;
use std::process::{Command, Output};

/// The binary under test, with a clean environment (no RUST_LOG surprises).
pub fn evalharness() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_evalharness"));
    c.env_remove("RUST_LOG").env("NO_COLOR", "1");
    c
}

/// Runs with `args` and returns the output.
pub fn run(args: &[&str]) -> Output {
    evalharness().args(args).output().expect("evalharness runs")
}

/// `args` with the value after `flag` replaced by `value` (the flag must be there).
pub fn with_flag<'a>(args: &[&'a str], flag: &str, value: &'a str) -> Vec<&'a str> {
    let mut args = args.to_vec();
    let at = args.iter().position(|a| *a == flag).unwrap_or_else(|| panic!("{flag} not in {args:?}")) + 1;
    args[at] = value;
    args
}

/// Asserts exit code `code` and returns (stdout, stderr).
pub fn expect_code(out: &Output, code: i32) -> (String, String) {
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(code), "stdout:\n{stdout}\nstderr:\n{stderr}");
    (stdout, stderr)
}

/// A temporary path as the `&str` an argument list takes.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// `results.json` without its timings, which differ between any two runs.
pub fn without_timing(mut v: serde_json::Value) -> serde_json::Value {
    v.as_object_mut().expect("results.json is an object").remove("timing");
    v
}

/// `dir/results.json` without its timings.
pub fn results(dir: &Path) -> serde_json::Value {
    without_timing(read_json(&dir.join("results.json")))
}

/// Reads a JSON file.
pub fn read_json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// All files under `dir`, relative paths with their bytes, sorted.
pub fn tree_bytes(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).expect("readable dir") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).expect("under dir").display().to_string();
                out.push((rel, std::fs::read(&p).expect("readable file")));
            }
        }
    }
    out.sort();
    out
}

/// Copies every file under `from` to the same relative path under `to`.
pub fn copy_dir(from: &Path, to: &Path) {
    for (rel, bytes) in tree_bytes(from) {
        let path = to.join(rel);
        std::fs::create_dir_all(path.parent().expect("a file has a parent")).expect("writable temp dir");
        std::fs::write(path, bytes).expect("writable temp dir");
    }
}

/// The shipped Push-T checkpoints.
pub const PUSHT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/checkpoints/pusht");

/// Two scripted checkpoints (no training needed) and a copy of the shipped world
/// model with its autoencoder, in `dir`; returns (policy set, world model).
pub fn pusht_inputs(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let set = dir.join("set");
    for name in ["noise000-lag0", "noise100-lag0"] {
        copy_dir(&Path::new(PUSHT).join("scripted").join(name), &set.join(name));
    }
    let models = dir.join("models");
    copy_dir(&Path::new(PUSHT).join("world_model"), &models.join("world_model"));
    copy_dir(&Path::new(PUSHT).join("autoencoder"), &models.join("autoencoder"));
    (set, models.join("world_model"))
}

/// A tiny paired run of `pusht_inputs`: 4 episodes in batches of 2, 6 steps, no report.
pub fn tiny_rank_args<'a>(set: &'a Path, wm: &'a Path, out: &'a Path) -> Vec<&'a str> {
    let mut v = vec!["rank", "--policies", s(set), "--world-model", s(wm), "--episodes", "4"];
    v.extend(["--max-steps", "6", "--batch", "2", "--bootstrap", "20", "--no-report", "--out", s(out)]);
    v
}

/// Writes `dir/name`: the shipped `scenarios/pusht.toml` with `from` replaced by `to`.
pub fn scenario_variant(dir: &Path, name: &str, from: &str, to: &str) -> std::path::PathBuf {
    let shipped = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/scenarios/pusht.toml"))
        .expect("shipped scenario file");
    assert!(shipped.contains(from), "pusht.toml has no '{from}'");
    let path = dir.join(name);
    std::fs::write(&path, shipped.replace(from, to)).expect("writable temp dir");
    path
}

/// The tiny models of a robosuite task that its pipeline tests rank with.
pub struct TinyArm {
    /// 10 episodes of the task's default mix, 12 steps each.
    pub data: std::path::PathBuf,
    /// An autoencoder of one training step.
    pub ae: std::path::PathBuf,
    /// A world model of one training step, in the latents of `ae`.
    pub wm: std::path::PathBuf,
    /// A judge of success of two training steps.
    pub judge: std::path::PathBuf,
    /// A folder of two policy checkpoints (`epoch-0001`, `epoch-0002`).
    pub pol: std::path::PathBuf,
    /// What `train judge` printed.
    pub judge_stdout: String,
}

/// Collects 10 × 12 steps of `scenario` under `dir` and trains every model on them
/// at tiny settings, each command expected to succeed.
pub fn tiny_arm_models(dir: &Path, scenario: &str) -> TinyArm {
    let data = dir.join(format!("{scenario}.zarr"));
    let collect =
        ["collect", "--scenario", scenario, "--episodes", "10", "--seed-start", "0", "--max-steps", "12"];
    expect_code(&run(&[&collect[..], &["--out", s(&data)]].concat()), 0);
    let ae = dir.join("ae");
    let args = ["train", "autoencoder", "--data", s(&data), "--out", s(&ae), "--steps", "1", "--batch", "2"];
    expect_code(&run(&args), 0);
    let wm = dir.join("wm");
    let train = ["train", "world-model", "--data", s(&data), "--autoencoder", s(&ae), "--out", s(&wm)];
    let tiny =
        ["--steps", "1", "--base-channels", "16", "--contexts", "2", "--samples", "2", "--eval-every", "1"];
    expect_code(&run(&[&train[..], &tiny[..]].concat()), 0);
    let judge = dir.join("judge");
    let args = ["train", "judge", "--data", s(&data), "--out", s(&judge), "--steps", "2", "--batch", "4"];
    let tiny = ["--encoder-width", "8", "--feature-dim", "8"];
    let (judge_stdout, _) = expect_code(&run(&[&args[..], &tiny[..]].concat()), 0);
    let pol = dir.join("pol");
    let args =
        ["train", "policy", "--data", s(&data), "--out", s(&pol), "--epochs", "2", "--behaviour", "all"];
    let tiny = ["--batch", "8", "--encoder-steps", "2", "--down-dims", "8,16", "--encoder-width", "8"];
    expect_code(&run(&[&args[..], &tiny[..]].concat()), 0);
    TinyArm { data, ae, wm, judge, pol, judge_stdout }
}

/// An `episodes.jsonl` line of this build in the layout written before 2026-12-02: Push-T's
/// named state and scene checks as fields of their own, `max_raw` as `max_coverage`.
pub fn old_row_layout(line: &str) -> String {
    let mut row: serde_json::Value = serde_json::from_str(line).unwrap();
    let o = row.as_object_mut().unwrap();
    let state = o.remove("state").unwrap();
    let scene = o.remove("scene").unwrap();
    let pose = |p: &str| -> Option<serde_json::Value> {
        let v: Option<Vec<f64>> =
            ["x", "y", "theta"].iter().map(|k| state[format!("{p}_{k}")].as_f64()).collect();
        v.map(|v| serde_json::json!(v))
    };
    o.insert("final_block".into(), pose("final_block").unwrap_or(serde_json::Value::Null));
    o.insert("goal".into(), pose("goal").unwrap());
    for (k, v) in scene.as_object().unwrap() {
        o.insert(k.clone(), v.clone());
    }
    for (new, old) in [("max_raw", "max_coverage"), ("final_raw", "final_coverage")] {
        let v = o.remove(new).unwrap();
        o.insert(old.into(), v);
    }
    format!("{row}\n")
}
