//! Side-by-side rollouts for the report: for each policy, the episodes where the
//! world model agreed best and worst with MuJoCo (smallest and largest
//! |imagined − real| score) are replayed with frame recording — the same seed,
//! policy noise and generator noise as in the run — and written as a filmstrip
//! (row 1 MuJoCo, row 2 world model, every `every`-th action chunk) and a GIF
//! with both branches side by side.

use std::path::{Path, PathBuf};

use anyhow::Result;
use harness::policy::Policy;
use world_model::model::WorldModel;

use engine::{Setup, Start, Timing, sim_branch, wm_branch};
use harness::results::{Branch, EpisodeRow};

/// The best- and worst-agreeing seeds of a policy (at most 2, distinct).
pub fn pick_seeds(rows: &[EpisodeRow], policy: &str) -> Vec<(u64, &'static str)> {
    let mut gaps: Vec<(f64, u64)> = Vec::new();
    for r in rows.iter().filter(|r| r.policy == policy && r.branch == Branch::Sim) {
        if let Some(w) =
            rows.iter().find(|w| w.policy == policy && w.seed == r.seed && w.branch == Branch::WorldModel)
        {
            gaps.push(((w.score - r.score).abs(), r.seed));
        }
    }
    gaps.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut out = Vec::new();
    if let Some(&(_, s)) = gaps.first() {
        out.push((s, "best"));
    }
    if let Some(&(_, s)) = gaps.last().filter(|l| gaps.len() > 1 && l.1 != gaps[0].1) {
        out.push((s, "worst"));
    }
    out
}

/// Writes `dir/<policy>_seed<seed>_<tag>.{png,gif}` for the picked seeds; returns
/// the filmstrip paths with captions.
///
/// # Errors
/// A failing replay or an unwritable file.
pub fn write_rollouts(
    dir: &Path,
    policy: &dyn Policy,
    picks: &[(u64, &'static str)],
    setup: &Setup,
    wm: &WorldModel,
    every: usize,
) -> Result<Vec<(PathBuf, String)>> {
    std::fs::create_dir_all(dir)?;
    let seeds: Vec<u64> = picks.iter().map(|p| p.0).collect();
    if seeds.is_empty() {
        return Ok(Vec::new());
    }
    let mut timing = Timing::default();
    let mut start = Start::new(policy.name(), &seeds, setup)?;
    start.record = true;
    let imagined = wm_branch(policy, &start, setup, wm, &mut timing)?;
    let real = sim_branch(policy, start, setup, &mut timing)?;
    let size = setup.task.observation_spec().image_size;
    let mut out = Vec::new();
    for (i, &(seed, tag)) in picks.iter().enumerate() {
        let (r, w) = (&real.frames[i], &imagined.frames[i]);
        let stem = format!("{}_seed{seed}_{tag}", policy.name());
        let rows = vec![
            r.iter().step_by(every.max(1)).cloned().collect(),
            w.iter().step_by(every.max(1)).cloned().collect(),
        ];
        let strip = reports::png::filmstrip(&rows, size, size);
        let png = dir.join(format!("{stem}.png"));
        reports::png::write_png(&png, &strip.pixels, strip.width, strip.height)?;
        let pair: Vec<Vec<u8>> = r.iter().zip(w).map(|(a, b)| side_by_side(a, b, size)).collect();
        let side = u16::try_from(size).unwrap_or(u16::MAX);
        reports::gif::write_gif(&dir.join(format!("{stem}.gif")), &pair, 2 * side, side, 200)?;
        let (rs, ws) = (real.rows[i].score, imagined.rows[i].score);
        out.push((
            png,
            format!(
                "{} seed {seed} ({tag} agreement): MuJoCo (top) score {rs:.2}, world model (bottom) score {ws:.2}; every {}th action chunk ({} steps)",
                policy.name(),
                every,
                every * policy.action_horizon()
            ),
        ));
    }
    Ok(out)
}

/// Two `size x size` RGB frames next to each other.
fn side_by_side(a: &[u8], b: &[u8], size: usize) -> Vec<u8> {
    let row = size * 3;
    let mut out = Vec::with_capacity(2 * a.len());
    for (ra, rb) in a.chunks_exact(row).zip(b.chunks_exact(row)) {
        out.extend_from_slice(ra);
        out.extend_from_slice(rb);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn picks_best_and_worst_agreement() {
        let row = |seed, b, s| EpisodeRow::new("p", seed, b, s, 0.0, 0.0, 0.95, 1);
        let rows = vec![
            row(1, Branch::Sim, 0.5),
            row(1, Branch::WorldModel, 0.1), // gap 0.4
            row(2, Branch::Sim, 0.5),
            row(2, Branch::WorldModel, 0.45), // gap 0.05
            row(3, Branch::Sim, 0.9),
        ];
        assert_eq!(pick_seeds(&rows, "p"), vec![(2, "best"), (1, "worst")]);
        assert!(pick_seeds(&rows, "q").is_empty());
    }

    #[test]
    fn side_by_side_interleaves_rows() {
        // 1x1 frames: [a][b] per row.
        assert_eq!(side_by_side(&[1, 2, 3], &[4, 5, 6], 1), vec![1, 2, 3, 4, 5, 6]);
    }
}
