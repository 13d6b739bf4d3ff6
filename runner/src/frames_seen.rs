//! Whether a run's models read frames of the scene the run renders.
//!
//! Only two things read a rendered frame: a policy's frame encoder and the world model's
//! autoencoder encoder (the world model imagines in latents, the judge reads decoded frames).
//! Each records the scene parameters of the frames it learned on, where it knows them: an
//! adapted folder in `adaptation.json` (`to`: the rendering it was adapted to), otherwise the
//! training data's recipe (`policy.json`'s or the autoencoder's `provenance.json`,
//! `data.collected_with.scenario_config`, recorded for data collected from 2026-12-03 on). A
//! model whose record differs from the run's task parameters (Lift's default rendering changed
//! on 2026-12-03, c37e799) would be ranked on frames it never saw, so `rank` says so on stderr,
//! naming the model and the parameters that differ. A model without a record is not judged.

use std::path::Path;

use harness::provenance::{AutoencoderProvenance, FramesUsed};
use serde::Deserialize;
use serde_json::Value;

/// The part of `adaptation.json` that says which frames the adapted folder reads.
#[derive(Deserialize)]
struct AdaptedTo {
    /// The episodes in the new rendering.
    to: FramesUsed,
}

/// The scene parameters recorded in `dir/adaptation.json`'s `to`, if the folder was adapted
/// and they were recorded.
fn adapted(dir: &Path) -> Option<Value> {
    let a: AdaptedTo = harness::provenance::read(&dir.join("adaptation.json")).ok()?;
    a.to.collected_with?.scenario_config
}

/// The scene parameters a policy checkpoint's frames came from, where recorded.
fn policy_scene(dir: &Path) -> Option<Value> {
    adapted(dir).or_else(|| {
        let file = policies::dir::read_policy_file(dir).ok()?;
        file.provenance.data?.collected_with?.scenario_config
    })
}

/// The scene parameters an autoencoder folder's frames came from, where recorded.
fn autoencoder_scene(dir: &Path) -> Option<Value> {
    adapted(dir).or_else(|| {
        let p: AutoencoderProvenance = harness::provenance::read(&dir.join("provenance.json")).ok()?;
        p.data.collected_with?.scenario_config
    })
}

/// The top-level parameters whose values differ between `recorded` and `now` (all of them,
/// as `"parameters"`, when either is not a table).
fn differing(recorded: &Value, now: &Value) -> Vec<String> {
    match (recorded, now) {
        (Value::Object(a), Value::Object(b)) => {
            let mut keys: Vec<&String> = a.keys().chain(b.keys()).collect();
            keys.sort();
            keys.dedup();
            keys.into_iter().filter(|k| a.get(*k) != b.get(*k)).cloned().collect()
        }
        _ if recorded == now => Vec::new(),
        _ => vec!["parameters".to_string()],
    }
}

/// A line for each of the run's frame readers (the policy checkpoints `policies`, the
/// autoencoder folder `autoencoder`) whose recorded frames came from other scene parameters
/// than `now`, the run's task's; `read` gives a record as the task writes one today
/// (`Task::recorded_parameters`: an older Lift or Can record left robosuite's rendering
/// implicit).
pub fn mismatches(
    now: &Value,
    read: &dyn Fn(&Value) -> Value,
    policies: &[std::path::PathBuf],
    autoencoder: Option<&Path>,
) -> Vec<String> {
    let readers = policies
        .iter()
        .map(|d| (format!("policy {}", policies::dir::checkpoint_name(d)), policy_scene(d)))
        .chain(autoencoder.map(|d| (format!("autoencoder {}", d.display()), autoencoder_scene(d))));
    readers
        .filter_map(|(name, recorded)| {
            let keys = differing(&read(&recorded?), now);
            (!keys.is_empty()).then(|| {
                format!(
                    "{name} learned on frames of other scene parameters than this run's ({}): it is \
                     ranked on frames it never saw; pass the scenario it learned on (for robosuite's \
                     rendering of Lift or Can, scenarios/lift_robosuite.toml or can_robosuite.toml)",
                    keys.join(", ")
                )
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A checkpoint folder whose `adaptation.json` records `scene` as its new rendering.
    fn adapted_to(dir: &Path, scene: &Value) {
        std::fs::create_dir_all(dir).unwrap();
        let frames = serde_json::json!({
            "collected_with": {"command": "evalharness collect", "evalharness_version": "0.1.0",
                               "scenario_config": scene},
            "episodes": 1, "frames": 1, "held_out": "none", "path": "d.zarr"});
        let a = serde_json::json!({"command": "train adapt", "to": frames});
        std::fs::write(dir.join("adaptation.json"), a.to_string()).unwrap();
    }

    #[test]
    fn a_model_is_named_when_its_frames_came_from_another_scene() {
        let tmp = tempfile::tempdir().unwrap();
        let as_is = |v: &Value| v.clone();
        let cheap = serde_json::json!({"max_steps": 400, "visual": {"samples": 0, "reflections": false}});
        let robosuite = serde_json::json!({"max_steps": 400, "visual": {"samples": 4, "reflections": true}});
        let (same, other, silent) =
            (tmp.path().join("epoch-0001"), tmp.path().join("epoch-0002"), tmp.path().join("epoch-0003"));
        adapted_to(&same, &cheap);
        adapted_to(&other, &robosuite);
        std::fs::create_dir_all(&silent).unwrap();
        let ae = tmp.path().join("ae");
        adapted_to(&ae, &robosuite);
        let got = mismatches(&cheap, &as_is, &[same.clone(), other, silent], Some(&ae));
        // The checkpoint on robosuite's frames and the autoencoder are named with the parameter
        // that differs; the matching one and the one without a record are not.
        assert_eq!(got.len(), 2, "{got:?}");
        assert!(got[0].starts_with("policy epoch-0002 learned on frames") && got[0].contains("(visual)"));
        assert!(got[1].starts_with("autoencoder ") && got[1].contains("(visual)"), "{got:?}");
        assert!(mismatches(&robosuite, &as_is, &[same], None)[0].contains("(visual)"));
        // A record is read as the task reads it: Can's, written before renderings were
        // recorded, was robosuite's rendering, so a run rendering robosuite's way does not name
        // it (read as it is, it would be), and one rendering the cheap way does.
        use scenarios::robosuite::visual::Visual;
        let legacy = tmp.path().join("epoch-0004");
        let can = scenarios::load_task("can").unwrap();
        let read = |v: &Value| can.recorded_parameters(v);
        let mut now = can.parameters().unwrap();
        now["visual"] = serde_json::to_value(Visual::robosuite()).unwrap();
        let mut written_then = now.clone();
        written_then.as_object_mut().unwrap().remove("visual");
        adapted_to(&legacy, &written_then);
        assert!(mismatches(&now, &read, std::slice::from_ref(&legacy), None).is_empty());
        assert_eq!(mismatches(&now, &as_is, std::slice::from_ref(&legacy), None).len(), 1);
        let mut cheap_now = now.clone();
        cheap_now["visual"] = serde_json::to_value(Visual::cheap()).unwrap();
        assert!(mismatches(&cheap_now, &read, &[legacy], None)[0].contains("(visual)"));
        assert_eq!(differing(&Value::Null, &Value::Null), Vec::<String>::new());
        assert_eq!(differing(&Value::Null, &cheap), ["parameters"]);
    }
}
