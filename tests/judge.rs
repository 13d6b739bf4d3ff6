//! `train judge` and `rank --judge`, on the pipeline test's tiny dataset, world model
//! and policies (called from `pipeline_end_to_end`).

use std::path::Path;

use crate::util::{expect_code, read_json, run, s};

/// Trains a tiny coverage judge on `data`, ranks `set` with it, and checks the refusals.
pub fn check(dir: &Path, data: &Path, wm: &Path, set: &Path) {
    let judge = dir.join("judge");
    let train = ["train", "judge", "--data", s(data), "--out", s(&judge)];
    let tiny =
        ["--steps", "3", "--batch", "4", "--encoder-width", "8", "--feature-dim", "8", "--eval-every", "2"];
    let (stdout, _) = expect_code(&run(&[&train[..], &tiny[..]].concat()), 0);
    assert!(stdout.contains("judge of coverage: held-out 68 frames"), "{stdout}");
    let file = read_json(&judge.join("judge.json"));
    // The dataset's coverage array is the label, success above 0.95; episode 9 (68
    // frames) is held out, and its reading is stored with the provenance.
    assert_eq!((file["label"].as_str(), file["threshold"].as_f64()), (Some("coverage"), Some(0.95)));
    assert_eq!(file["heldout"]["frames"], 68);
    // ...and read whole: one held-out episode, with a count of the episodes read right.
    assert_eq!(file["heldout"]["episodes"]["episodes"], 1);
    assert!(stdout.contains("whole episodes (success held for 1 judged frame(s)): "), "{stdout}");
    assert!(stdout.contains(" of 1 read right"), "{stdout}");
    // The reading is rank's: the first frame and the last 2 of every 8 steps, 1 in a row.
    let reading = &file["heldout"]["episodes"]["reading"];
    assert_eq!((reading["chunk"].as_u64(), reading["seen"].as_u64()), (Some(8), Some(2)), "{file}");
    assert_eq!(file["persist_frames"], 1);
    assert!(file["heldout"]["mean_abs_error"].as_f64().unwrap().is_finite());
    assert_eq!(file["provenance"]["data"]["episodes"], 10);
    assert_eq!(file["provenance"]["train"]["steps"], 3);
    // Evaluations at steps 2 and 3 (the last).
    let log = std::fs::read_to_string(judge.join("log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 2, "{log}");
    // An existing judge is kept without --force; with it, replaced once the new one is done.
    let (_, err) = expect_code(&run(&[&train[..], &tiny[..]].concat()), 2);
    assert!(err.contains("already exists"), "{err}");
    expect_code(&run(&[&train[..], &tiny[..], &["--force"]].concat()), 0);
    assert!(!dir.join("judge.replaced").exists());
    let heldout = read_json(&judge.join("judge.json"))["heldout"].clone();
    // A label the dataset lacks is named.
    let (_, err) =
        expect_code(&run(&[&train[..], &tiny[..], &["--force", "--label", "success"]].concat()), 2);
    assert!(err.contains("data/success"), "{err}");
    assert!(judge.join("judge.json").is_file(), "the old judge stays when the new one fails");
    resumes(dir, data, &tiny, &heldout);

    // rank --judge: the learned judge scores the imagined frames; its error on the
    // simulator branch's real frames is reported as for any judge.
    let out = dir.join("rank_judge");
    let rank = ["rank", "--policies", s(set), "--world-model", s(wm), "--episodes", "2", "--max-steps", "8"];
    let args =
        [&rank[..], &["--bootstrap", "20", "--no-report", "--judge", s(&judge), "--out", s(&out)]].concat();
    expect_code(&run(&args), 0);
    let config = read_json(&out.join("config.json"));
    assert_eq!(config["judge"]["label"], "coverage");
    assert!(config["fingerprints"]["judge"].is_string(), "{config}");
    let res = read_json(&out.join("results.json"));
    let err = res["policies"][0]["frame_scorer_mean_abs_error"].as_f64();
    assert!(err.is_some_and(|e| (0.0..=1.0).contains(&e)), "{res}");
    // A judge of another label, or a folder without a judge, is refused before anything runs.
    let mut other = read_json(&judge.join("judge.json"));
    other["label"] = serde_json::json!("success");
    other["threshold"] = serde_json::json!(0.5);
    let wrong = dir.join("judge_success");
    std::fs::create_dir_all(&wrong).unwrap();
    std::fs::copy(judge.join("model.bpk"), wrong.join("model.bpk")).unwrap();
    std::fs::write(wrong.join("judge.json"), serde_json::to_string(&other).unwrap()).unwrap();
    let out2 = dir.join("rank_judge_wrong");
    let args = [&rank[..], &["--judge", s(&wrong), "--out", s(&out2)]].concat();
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("judge_success") && err.contains("estimates success"), "{err}");
    assert!(!out2.exists());
    let args = [&rank[..], &["--judge", s(set), "--out", s(&out2)]].concat();
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("judge.json"), "{err}");
}

/// A judge run resumes as the other trainers' do, to the judge an uninterrupted run ends
/// with (`heldout`, the held-out reading of the 3-step judge of `tiny`, every figure to the
/// last bit; the unit test `a_stopped_session_resumes_to_the_weights_of_an_uninterrupted_run`
/// compares the weights): from a session out of time before its first step, and from a
/// finished 2-step run extended by `--steps 3`, whose optimiser state the checkpoint carries.
fn resumes(dir: &Path, data: &Path, tiny: &[&str], heldout: &serde_json::Value) {
    let none = dir.join("judge_no_time");
    let args = [&["train", "judge", "--data", s(data), "--out", s(&none)][..], tiny].concat();
    let (stdout, _) = expect_code(&run(&[&args[..], &["--max-minutes", "0"]].concat()), 0);
    assert!(stdout.contains("stopped before its first step; --resume continues"), "{stdout}");
    assert!(!none.join("judge.json").exists() && none.join(".train/state.json").is_file());
    // Without --resume the run is refused; a flag that contradicts the saved run is named.
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("--resume"), "{err}");
    let (_, err) = expect_code(&run(&[&args[..], &["--resume", "--lr", "0.5"]].concat()), 2);
    assert!(err.contains("--lr (saved: 0.001)"), "{err}");
    let (stdout, _) = expect_code(&run(&[&args[..], &["--resume"]].concat()), 0);
    assert!(stdout.contains("judge of coverage"), "{stdout}");
    let file = read_json(&none.join("judge.json"));
    assert_eq!(&file["heldout"], heldout, "resumed from step 0");
    assert_eq!(
        (file["steps"].as_u64(), file["provenance"]["sessions"].as_array().map(Vec::len)),
        (Some(3), Some(2))
    );
    assert!(file["provenance"].get("out_of_time").is_none(), "{file}");

    // Two steps, then one more: the same weights as three in one go.
    let ext = dir.join("judge_extended");
    // `tiny` opens with `--steps 3`.
    let rest = &tiny[2..];
    let two =
        [&["train", "judge", "--data", s(data), "--out", s(&ext)][..], rest, &["--steps", "2"]].concat();
    expect_code(&run(&two), 0);
    assert_eq!(read_json(&ext.join("judge.json"))["steps"], 2);
    let three = [&two[..two.len() - 2], &["--steps", "3", "--resume"]].concat();
    let (stdout, _) = expect_code(&run(&three), 0);
    assert!(!stdout.contains("stopped early"), "{stdout}");
    assert_eq!(&read_json(&ext.join("judge.json"))["heldout"], heldout, "resumed from step 2");
    // The log keeps one history: the evaluation at step 2 (the first run's last), then step 3.
    let log = std::fs::read_to_string(ext.join("log.jsonl")).unwrap();
    let steps: Vec<u64> = log
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["step"].as_u64().unwrap())
        .collect();
    assert_eq!(steps, [2, 3], "{log}");
}
