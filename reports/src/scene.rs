//! Did the world model keep the scene? A health check of the imagined frames.
//!
//! The imagined branch is scored from frames, and a long autoregressive rollout
//! can lose the scene: Push-T's block erodes or smears, the (static) goal fades, the
//! agent vanishes. The judge then still reads a score — from a blob. A task's judge
//! may check the last frame the policy saw ([`SceneCheck`]: named fractions of the
//! scene still shown, about 1 on real frames; Push-T's `block_area`, `goal_kept`,
//! `agent_kept`); every episode row records them by name ([`EpisodeRow::scene`]),
//! `results.json` averages each per policy and branch, with MuJoCo's as the reference.
//! This module turns them into the sentence the report shows, and a warning naming the
//! policies whose imagined episodes end with less than half of a checked part.
//!
//! [`SceneCheck`]: harness::judge::SceneCheck
//! [`EpisodeRow::scene`]: harness::results::EpisodeRow::scene

use std::collections::BTreeSet;

use harness::results::PolicyResult;

/// Below this mean (a checked part's fraction still shown) a policy's imagined episodes end
/// in frames that have lost the scene.
pub const DEGRADED: f64 = 0.5;

/// The sentence on the checks, and whether it warns; `None` for runs that did not record
/// them. Each check is stated where every policy's world-model branch and at least one
/// MuJoCo branch made it (a check that some policies lack, as in runs written before the
/// check existed, is left out).
pub fn scene_note(pol: &[PolicyResult], simulator: &str) -> Option<(String, bool)> {
    let names: BTreeSet<&str> =
        pol.iter().flat_map(|p| p.world_model.scene.keys().map(String::as_str)).collect();
    let mut parts = Vec::new();
    let mut bad = Vec::new();
    for name in names {
        let wm: Vec<(&str, f64)> =
            pol.iter().filter_map(|p| Some((p.name.as_str(), *p.world_model.scene.get(name)?))).collect();
        let sim: Vec<f64> = pol.iter().filter_map(|p| p.sim.scene.get(name).copied()).collect();
        if wm.len() < pol.len() || sim.is_empty() {
            continue;
        }
        let (lo, hi) =
            wm.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), w| (l.min(w.1), h.max(w.1)));
        let sim_mean = sim.iter().sum::<f64>() / sim.len() as f64;
        parts.push(format!(
            "{}: {simulator} {sim_mean:.2} on average, world model {lo:.2}–{hi:.2} across policies",
            name.replace('_', " ")
        ));
        bad.extend(wm.iter().filter(|w| w.1 < DEGRADED).map(|w| w.0));
    }
    if parts.is_empty() {
        return None;
    }
    let mut text = format!(
        "Scene kept at the end of the episodes (the task's judge's checks of the last frame the policy saw, \
         each the fraction of a part of the scene still shown, about 1 on real frames): {}.",
        parts.join("; ")
    );
    // In run order, each policy once.
    let bad: Vec<&str> = pol.iter().map(|p| p.name.as_str()).filter(|n| bad.contains(n)).collect();
    if !bad.is_empty() {
        text.push_str(&format!(
            " The imagined episodes of {} end with less than half of a checked part of the scene: the world \
             model's rollout lost the scene, and these imagined scores come from degraded frames.",
            bad.join(", ")
        ));
    }
    Some((text, !bad.is_empty()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use harness::judge::SceneCheck;
    use harness::results::{Branch, EpisodeRow};
    use harness::summarise::summarise;

    #[test]
    fn names_policies_whose_imagined_scene_degraded() {
        // (policy, MuJoCo (block, goal, agent), world model (block, goal, agent)) per episode:
        // a: world-model blocks 0.9, 0.9 but goal 0.2, 0.4 (mean 0.3 < 0.5): degraded;
        // b: world model (0.8, 0.9, 1.0), (0.6, 0.7, 0.8): means 0.7, 0.8, 0.9, fine;
        // c: block and goal fine, but the agent 0.1 and 0.3 (mean 0.2 < 0.5): degraded.
        let eps = [
            ("a", (1.06, 0.95, 1.0), (0.9, 0.2, 0.9)),
            ("a", (1.06, 0.97, 1.0), (0.9, 0.4, 0.9)),
            ("b", (1.04, 0.95, 1.0), (0.8, 0.9, 1.0)),
            ("b", (1.06, 0.93, 0.98), (0.6, 0.7, 0.8)),
            ("c", (1.05, 0.95, 1.0), (0.9, 0.9, 0.1)),
            ("c", (1.05, 0.95, 1.0), (0.9, 0.9, 0.3)),
        ];
        let check = |(b, g, a)| SceneCheck(vec![("block_area", b), ("goal_kept", g), ("agent_kept", a)]);
        let rows: Vec<EpisodeRow> = eps
            .iter()
            .enumerate()
            .flat_map(|(i, &(p, sim, wm))| {
                let row = |b| EpisodeRow::new(p, i as u64, b, 0.5, 0.4, 0.4, 0.95, 10);
                [
                    row(Branch::Sim).with_scene(Some(&check(sim))),
                    row(Branch::WorldModel).with_scene(Some(&check(wm))),
                ]
            })
            .collect();
        let names = ["a".into(), "b".into(), "c".into()];
        let (s, _) = summarise(&rows, &names, 100, 0);
        assert!((s[0].world_model.scene["goal_kept"] - 0.3).abs() < 1e-12);
        assert!((s[2].world_model.scene["agent_kept"] - 0.2).abs() < 1e-12);
        let (text, warn) = scene_note(&s, "MuJoCo").unwrap();
        assert!(warn);
        // MuJoCo block area: policy means 1.06, 1.05, 1.05 → 1.0533; goal: (0.96 + 0.94 + 0.95) / 3
        // = 0.95; agent: (1.0 + 0.99 + 1.0) / 3 = 0.9967 → "1.00". World model block 0.70–0.90,
        // goal 0.30–0.90, agent 0.20–0.90. In the checks' name order: agent, block, goal.
        let want = "agent kept: MuJoCo 1.00 on average, world model 0.20–0.90 across policies; \
                    block area: MuJoCo 1.05 on average, world model 0.70–0.90 across policies; \
                    goal kept: MuJoCo 0.95 on average, world model 0.30–0.90 across policies.";
        assert!(text.contains(want), "{text}");
        assert!(text.contains("episodes of a, c end"), "{text}");
        // Runs written before the agent check (no policy has it): the block and goal only.
        let older: Vec<EpisodeRow> = rows
            .iter()
            .cloned()
            .map(|mut r| {
                r.scene.remove("agent_kept");
                r
            })
            .collect();
        let (text, _) = scene_note(&summarise(&older, &names, 100, 0).0, "MuJoCo").unwrap();
        assert!(!text.contains("agent kept") && text.contains("episodes of a end"), "{text}");
        // Without the checks (a task whose judge makes none): no note.
        let plain: Vec<EpisodeRow> = rows.into_iter().map(|r| r.with_scene(None)).collect();
        assert_eq!(scene_note(&summarise(&plain, &["a".into()], 100, 0).0, "MuJoCo"), None);
    }
}
