//! Did the world model keep the scene? A health check of the imagined frames.
//!
//! The imagined branch is scored from frames, and a long autoregressive rollout
//! can lose the scene: the block erodes or smears, the (static) goal fades, the
//! agent vanishes. The scorer then still reads a coverage — from a blob. Every
//! episode row records three checks of the last frame the policy saw
//! ([`EpisodeRow::block_area`], [`EpisodeRow::goal_kept`], [`EpisodeRow::agent_kept`]);
//! `results.json` averages them per policy and branch, with MuJoCo's as the
//! reference. This module turns them into the sentence the report shows, and a
//! warning naming the policies whose imagined episodes end with less than half of
//! the goal, of the block or of the agent.
//!
//! [`EpisodeRow::block_area`]: harness::results::EpisodeRow::block_area
//! [`EpisodeRow::goal_kept`]: harness::results::EpisodeRow::goal_kept
//! [`EpisodeRow::agent_kept`]: harness::results::EpisodeRow::agent_kept

use harness::results::PolicyResult;

/// Below this mean (block area, or fraction of the goal or of the agent shown) a policy's
/// imagined episodes end in frames that have lost the scene.
pub const DEGRADED: f64 = 0.5;

/// The sentence on both checks, and whether it warns; `None` for runs that did not
/// record them.
pub fn scene_note(pol: &[PolicyResult]) -> Option<(String, bool)> {
    // The agent check is absent in runs written before it existed.
    let wm: Vec<(&str, f64, f64, Option<f64>)> = pol
        .iter()
        .filter_map(|p| {
            let w = &p.world_model;
            Some((p.name.as_str(), w.block_area?, w.goal_kept?, w.agent_kept))
        })
        .collect();
    let sim: Vec<(f64, f64)> =
        pol.iter().filter_map(|p| Some((p.sim.block_area?, p.sim.goal_kept?))).collect();
    if wm.is_empty() || sim.is_empty() {
        return None;
    }
    let mean = |v: &mut dyn Iterator<Item = f64>| {
        let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
        s / n as f64
    };
    let range = |v: &mut dyn Iterator<Item = f64>| {
        v.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| (l.min(x), h.max(x)))
    };
    let (b_lo, b_hi) = range(&mut wm.iter().map(|w| w.1));
    let (g_lo, g_hi) = range(&mut wm.iter().map(|w| w.2));
    let mut text = format!(
        "Scene kept at the end of the episodes (the last frame the policy saw): block pixels as a fraction \
         of the T's area, MuJoCo {:.2} on average, world model {b_lo:.2}–{b_hi:.2} across policies; \
         fraction of the goal T still shown, MuJoCo {:.2}, world model {g_lo:.2}–{g_hi:.2}.",
        mean(&mut sim.iter().map(|s| s.0)),
        mean(&mut sim.iter().map(|s| s.1)),
    );
    let sim_agent: Vec<f64> = pol.iter().filter_map(|p| p.sim.agent_kept).collect();
    let wm_agent: Vec<f64> = wm.iter().filter_map(|w| w.3).collect();
    if !sim_agent.is_empty() && wm_agent.len() == wm.len() {
        let (a_lo, a_hi) = range(&mut wm_agent.iter().copied());
        text.push_str(&format!(
            " Fraction of the agent's disk still shown: MuJoCo {:.2}, world model {a_lo:.2}–{a_hi:.2}.",
            mean(&mut sim_agent.iter().copied())
        ));
    }
    let lost = |w: &(&str, f64, f64, Option<f64>)| {
        w.1 < DEGRADED || w.2 < DEGRADED || w.3.is_some_and(|a| a < DEGRADED)
    };
    let bad: Vec<&str> = wm.iter().filter(|w| lost(w)).map(|w| w.0).collect();
    if !bad.is_empty() {
        text.push_str(&format!(
            " The imagined episodes of {} end with less than half of the block, of the goal or of the agent: \
             the world model's rollout lost the scene, and these imagined scores come from degraded frames.",
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
        let check =
            |(block_area, goal_kept, agent_kept)| Some(SceneCheck { block_area, goal_kept, agent_kept });
        let rows: Vec<EpisodeRow> = eps
            .iter()
            .enumerate()
            .flat_map(|(i, &(p, sim, wm))| {
                let row = |b| EpisodeRow::new(p, i as u64, b, 0.5, 0.4, 0.4, 0.95, 10);
                [row(Branch::Sim).with_scene(check(sim)), row(Branch::WorldModel).with_scene(check(wm))]
            })
            .collect();
        let names = ["a".into(), "b".into(), "c".into()];
        let (s, _) = summarise(&rows, &names, 100, 0);
        assert!((s[0].world_model.goal_kept.unwrap() - 0.3).abs() < 1e-12);
        assert!((s[2].world_model.agent_kept.unwrap() - 0.2).abs() < 1e-12);
        let (text, warn) = scene_note(&s).unwrap();
        assert!(warn);
        // MuJoCo block area: policy means 1.06, 1.05, 1.05 → 1.0533; goal: (0.96 + 0.94 + 0.95) / 3
        // = 0.95; agent: (1.0 + 0.99 + 1.0) / 3 = 0.9967 → "1.00". World model block 0.70–0.90,
        // goal 0.30–0.90, agent 0.20–0.90.
        assert!(
            text.contains("world model 0.70–0.90") && text.contains("MuJoCo 0.95, world model 0.30–0.90"),
            "{text}"
        );
        assert!(text.contains("agent's disk still shown: MuJoCo 1.00, world model 0.20–0.90"), "{text}");
        assert!(text.contains("episodes of a, c end"), "{text}");
        // Runs written before the agent check: the block and goal sentence only.
        let older: Vec<EpisodeRow> = rows
            .iter()
            .cloned()
            .map(|mut r| {
                r.agent_kept = None;
                r
            })
            .collect();
        let (text, _) = scene_note(&summarise(&older, &names, 100, 0).0).unwrap();
        assert!(!text.contains("agent's disk") && text.contains("episodes of a end"), "{text}");
        // Without the checks (older runs): no note.
        let plain: Vec<EpisodeRow> = rows.into_iter().map(|r| r.with_scene(None)).collect();
        assert_eq!(scene_note(&summarise(&plain, &["a".into()], 100, 0).0), None);
    }
}
