//! `train adapt` on tiny models: a Lift model folder adapted to frames with the floor's
//! reflections (another rendering than Lift's default), the same command giving the same
//! weights twice, then ranked with them; inputs that do not pair up refused.
//! Run by the Lift pipeline test (`lift_models`), on the tiny models it trains.

use std::path::Path;

use crate::util::{TinyArm, copy_dir, expect_code, read_json, run, s, with_flag};

/// Lays the tiny models out as `checkpoints/lift`, adapts them to frames with reflections
/// and ranks the adapted folder on such frames. (A smaller shadow map would not do: Lift's
/// light casts no shadow, so it renders the same bytes.)
pub fn a_model_folder_adapted_to_another_rendering_ranks_with_it(dir: &Path, tiny: &TinyArm) {
    let TinyArm { data, ae, wm, judge, pol, .. } = tiny;
    let dir = &dir.join("adapt");
    // The model folder as `checkpoints/lift` lays it out.
    let models = dir.join("models");
    copy_dir(pol, &models.join("policies"));
    copy_dir(ae, &models.join("autoencoder"));
    copy_dir(judge, &models.join("judge"));
    copy_dir(wm, &models.join("world_model"));
    let cfg_path = models.join("world_model/config.json");
    let mut cfg = read_json(&cfg_path);
    cfg["model"]["autoencoder"] = serde_json::json!("../autoencoder");
    std::fs::write(&cfg_path, cfg.to_string()).unwrap();
    // The same 10 episodes (seeds, behaviours, steps) rendered another way.
    let scene = dir.join("reflecting.toml");
    std::fs::write(&scene, "name = \"lift\"\n\n[visual]\nreflections = true\n").unwrap();
    let to = dir.join("reflecting.zarr");
    let collect =
        ["collect", "--scenario", s(&scene), "--episodes", "10", "--seed-start", "0", "--max-steps", "12"];
    expect_code(&run(&[&collect[..], &["--out", s(&to)]].concat()), 0);

    let out = dir.join("adapted");
    let args = ["train", "adapt", "--models", s(&models), "--from", s(data), "--to", s(&to)];
    let tiny = ["--steps", "3", "--ae-steps", "2", "--batch", "4", "--out", s(&out)];
    let (stdout, _) = expect_code(&run(&[&args[..], &tiny[..]].concat()), 0);
    // Both checkpoints were trained on one frozen encoder: it is distilled once.
    assert_eq!(
        stdout.matches("policy encoder of epoch-0001, epoch-0002: held-out feature error").count(),
        1,
        "{stdout}"
    );
    assert!(stdout.contains("autoencoder: held-out feature error on the new frames"), "{stdout}");
    assert!(
        stdout
            .contains("policy encoder of epoch-0001, epoch-0002: held-out decision error on the new frames"),
        "{stdout}"
    );
    let adaptation = read_json(&out.join("adaptation.json"));
    assert_eq!(adaptation["held_out"], "episodes with index % 10 == 9", "{adaptation}");
    assert_eq!(adaptation["policy_encoders"]["steps"], 3);
    assert_eq!(adaptation["autoencoder_encoder"]["steps"], 2);
    let distilled = adaptation["distilled"].as_array().cloned().unwrap_or_default();
    assert_eq!(distilled.len(), 2, "{adaptation}");
    for d in &distilled {
        // Before distillation the original encoder reads the old frames exactly.
        assert_eq!(d["before"][0], 0.0, "{d}");
        assert!(d["before"][1].as_f64().is_some_and(|e| e > 0.0), "the new frames differ: {d}");
    }
    // The policies' decisions are measured too (the autoencoder has none): the original
    // encoder decides as itself on the old frames, otherwise on the new.
    assert_eq!(distilled[0]["decisions"][0][0], 0.0, "{adaptation}");
    assert!(distilled[0]["decisions"][0][1].as_f64().is_some_and(|e| e > 0.0), "{adaptation}");
    assert!(distilled[0]["decisions"][1][1].as_f64().is_some_and(f64::is_finite), "{adaptation}");
    assert!(distilled[1].get("decisions").is_none(), "{adaptation}");
    for part in ["policies/epoch-0001", "policies/epoch-0002", "autoencoder"] {
        assert_eq!(read_json(&out.join(part).join("adaptation.json")), adaptation, "{part}");
    }
    // The world model and judge are copied as they were; the world model reads the adapted
    // autoencoder beside it.
    for f in ["world_model/config.json", "world_model/ema.bpk", "judge/judge.json"] {
        assert_eq!(std::fs::read(out.join(f)).unwrap(), std::fs::read(models.join(f)).unwrap(), "{f}");
    }
    assert_ne!(
        std::fs::read(out.join("autoencoder/model.bpk")).unwrap(),
        std::fs::read(models.join("autoencoder/model.bpk")).unwrap()
    );
    // The same command again gives the same weights and errors (its seed drives every draw).
    let out_b = dir.join("adapted-again");
    expect_code(&run(&[&args[..], &with_flag(&tiny, "--out", s(&out_b))[..]].concat()), 0);
    for f in ["autoencoder/model.bpk", "policies/epoch-0001/model.bpk", "policies/epoch-0002/model.bpk"] {
        let (first, again) = (std::fs::read(out.join(f)).unwrap_or_default(), std::fs::read(out_b.join(f)));
        assert!(!first.is_empty() && again.ok() == Some(first), "{f} differs between two runs");
    }
    assert_eq!(read_json(&out_b.join("adaptation.json"))["distilled"], adaptation["distilled"]);

    // The adapted folder ranks on the frames it was adapted to.
    let rank = dir.join("rank");
    let (set, world, judged) = (out.join("policies"), out.join("world_model"), out.join("judge"));
    let args = ["rank", "--scenario", s(&scene), "--policies", s(&set)];
    let models_of = ["--world-model", s(&world), "--judge", s(&judged)];
    let size = ["--episodes", "1", "--max-steps", "4", "--no-report", "--out", s(&rank)];
    let (_, err) = expect_code(&run(&[&args[..], &models_of[..], &size[..]].concat()), 0);
    assert_eq!(read_json(&rank.join("results.json"))["policies"].as_array().map(Vec::len), Some(2));
    assert!(!err.contains("learned on frames of other scene parameters"), "{err}");
    // The folder before adaptation, on these frames: each policy and the autoencoder are
    // named, with the parameter that differs (their data was rendered Lift's default way).
    let (old_set, old_world, rank0) =
        (models.join("policies"), models.join("world_model"), dir.join("rank0"));
    let unadapted = ["rank", "--scenario", s(&scene), "--policies", s(&old_set)];
    let models_of = ["--world-model", s(&old_world), "--judge", s(&judged)];
    let size = ["--episodes", "1", "--max-steps", "4", "--no-report", "--out", s(&rank0)];
    let (_, err) = expect_code(&run(&[&unadapted[..], &models_of[..], &size[..]].concat()), 0);
    let said = "learned on frames of other scene parameters than this run's (visual)";
    assert_eq!(err.matches(said).count(), 3, "{err}");
    for name in ["policy epoch-0001 learned", "policy epoch-0002 learned", "autoencoder "] {
        assert!(err.contains(name), "{name}: {err}");
    }

    // Other episodes in --to, or an output over a finished one, are refused before anything runs.
    let other = dir.join("other.zarr");
    let collect =
        ["collect", "--scenario", s(&scene), "--episodes", "10", "--seed-start", "50", "--max-steps", "12"];
    expect_code(&run(&[&collect[..], &["--out", s(&other)]].concat()), 0);
    let out2 = dir.join("adapted2");
    let args =
        ["train", "adapt", "--models", s(&models), "--from", s(data), "--to", s(&other), "--out", s(&out2)];
    let (_, stderr) = expect_code(&run(&args), 2);
    assert!(stderr.contains("do not hold the same episodes"), "{stderr}");
    assert!(!out2.exists());
    let again =
        ["train", "adapt", "--models", s(&models), "--from", s(data), "--to", s(&to), "--out", s(&out)];
    let (_, stderr) = expect_code(&run(&again), 2);
    assert!(stderr.contains("--force"), "{stderr}");
}
