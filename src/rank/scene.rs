//! Did the world model keep the scene? A health check of the imagined frames.
//!
//! The imagined branch is scored from frames, and a long autoregressive rollout
//! can lose the scene: the block erodes or smears, the (static) goal fades. The
//! scorer then still reads a coverage — from a blob. Every episode row records two
//! checks of the last frame the policy saw ([`EpisodeRow::block_area`],
//! [`EpisodeRow::goal_kept`]); `results.json` averages them per policy and branch,
//! with MuJoCo's as the reference. This module turns them into the sentence the
//! report shows, and a warning naming the policies whose imagined episodes end with
//! less than half of the goal or of the block.
//!
//! [`EpisodeRow::block_area`]: super::results::EpisodeRow::block_area
//! [`EpisodeRow::goal_kept`]: super::results::EpisodeRow::goal_kept

use serde_json::Value;

/// Below this mean (block area, or fraction of the goal shown) a policy's imagined
/// episodes end in frames that have lost the scene.
pub const DEGRADED: f64 = 0.5;

/// The sentence on both checks, and whether it warns; `None` for runs that did not
/// record them.
pub fn scene_note(res: &Value) -> Option<(String, bool)> {
    let pol = res["policies"].as_array()?;
    let get = |p: &Value, b: &str, k: &str| p[b][k].as_f64();
    let wm: Vec<(&str, f64, f64)> = pol
        .iter()
        .filter_map(|p| {
            Some((
                p["name"].as_str()?,
                get(p, "world_model", "block_area")?,
                get(p, "world_model", "goal_kept")?,
            ))
        })
        .collect();
    let sim: Vec<(f64, f64)> = pol
        .iter()
        .filter_map(|p| Some((get(p, "sim", "block_area")?, get(p, "sim", "goal_kept")?)))
        .collect();
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
    let bad: Vec<&str> = wm.iter().filter(|w| w.1 < DEGRADED || w.2 < DEGRADED).map(|w| w.0).collect();
    if !bad.is_empty() {
        text.push_str(&format!(
            " The imagined episodes of {} end with less than half of the block or of the goal: the world \
             model's rollout lost the scene, and these imagined scores come from degraded frames.",
            bad.join(", ")
        ));
    }
    Some((text, !bad.is_empty()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rank::results::{Branch, EpisodeRow, summarise};

    #[test]
    fn names_policies_whose_imagined_scene_degraded() {
        // (policy, MuJoCo (area, goal), world model (area, goal)) per episode:
        // a: world-model areas 0.9, 0.9 but goal 0.2, 0.4 (mean 0.3 < 0.5): degraded;
        // b: world model (0.8, 0.9), (0.6, 0.7): means 0.7 and 0.8, fine.
        let eps = [
            ("a", (1.06, 0.95), (0.9, 0.2)),
            ("a", (1.06, 0.97), (0.9, 0.4)),
            ("b", (1.04, 0.95), (0.8, 0.9)),
            ("b", (1.06, 0.93), (0.6, 0.7)),
        ];
        let rows: Vec<EpisodeRow> = eps
            .iter()
            .enumerate()
            .flat_map(|(i, &(p, sim, wm))| {
                let row = |b| EpisodeRow::new(p, i as u64, b, 0.5, 0.4, 0.4, 0.95, 10);
                [row(Branch::Sim).with_scene(Some(sim)), row(Branch::WorldModel).with_scene(Some(wm))]
            })
            .collect();
        let s = summarise(&rows, &["a".into(), "b".into()], 100, 0);
        assert!((s["policies"][0]["world_model"]["goal_kept"].as_f64().unwrap() - 0.3).abs() < 1e-12);
        let (text, warn) = scene_note(&s).unwrap();
        assert!(warn);
        // MuJoCo block area: policy means 1.06 and 1.05, their mean 1.055 → "1.05" or "1.06";
        // goal: (0.96 + 0.94) / 2 = 0.95. World model block 0.70–0.90, goal 0.30–0.80.
        assert!(
            text.contains("world model 0.70–0.90") && text.contains("MuJoCo 0.95, world model 0.30–0.80"),
            "{text}"
        );
        assert!(text.contains("episodes of a end"), "{text}");
        // Without the checks (older runs): no note.
        let plain: Vec<EpisodeRow> = rows.into_iter().map(|r| r.with_scene(None)).collect();
        assert_eq!(scene_note(&summarise(&plain, &["a".into()], 100, 0)), None);
    }
}
