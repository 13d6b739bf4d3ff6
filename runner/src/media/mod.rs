//! Side-by-side rollouts for the report: for each policy, the episodes where the
//! world model agreed best and worst with MuJoCo (smallest and largest
//! |imagined − real| score), written as a filmstrip (row 1 MuJoCo, row 2 world model,
//! every `every`-th action chunk) and a GIF with both branches side by side.
//!
//! A run records every episode's frames at the end of each action chunk and keeps,
//! per policy, those of the best- and worst-agreeing episode so far ([`Kept`]), so the
//! filmstrips come from the run itself. An episode the run did not make here (rows of
//! a resumed run's earlier process, or of shard processes) is replayed: the same seed,
//! policy noise and generator noise give the same frames (a batch's episodes do not
//! depend on one another).

use std::path::{Path, PathBuf};

pub mod kept;

use engine::schedule::{Batch, EpisodeFrames, run_batches};
use engine::{EngineError, Setup};
use harness::policy::Policy;
use harness::results::{Branch, EpisodeRow};
use world_model::model::WorldModel;

use crate::error::RunError;
use kept::{Kept, gaps, order};

type Result<T, E = RunError> = std::result::Result<T, E>;

/// The most bytes of recorded frames the batches in flight may hold; above it a run
/// records nothing and its filmstrips replay the picked episodes' batches.
const RECORD_BUDGET: usize = 1 << 30;

/// Whether recording every episode's frames (both branches, one frame per action chunk
/// of the shortest-acting policy, the first frame too) fits [`RECORD_BUDGET`] with one
/// batch per worker and one more waiting to be handed on.
pub fn recording_fits(policies: &[&dyn Policy], setup: &Setup, batch: usize, jobs: usize) -> bool {
    let horizon = policies.iter().map(|p| p.action_horizon().max(1)).min().unwrap_or(1);
    let side = setup.task.observation_spec().image_size;
    let per_episode = 2 * (setup.max_steps.div_ceil(horizon) + 1) * side * side * 3;
    per_episode.saturating_mul(batch).saturating_mul(jobs.max(1) + 1) <= RECORD_BUDGET
}

/// The best- and worst-agreeing seeds of a policy (at most 2, distinct).
pub fn pick_seeds(rows: &[EpisodeRow], policy: &str) -> Vec<(u64, &'static str)> {
    let mut gaps = gaps(rows, policy);
    gaps.sort_by(|a, b| order(*a, *b));
    let mut out = Vec::new();
    if let Some(&(_, s)) = gaps.first() {
        out.push((s, "best"));
    }
    if let Some(&(_, s)) = gaps.last().filter(|l| gaps.len() > 1 && l.1 != gaps[0].1) {
        out.push((s, "worst"));
    }
    out
}

/// What the filmstrips are made from: the run's rows and batches (the seeds of each, as
/// `--batch` cut them), the frames it kept, and what replays the others.
pub struct Sources<'a> {
    /// Every row of the run, resumed ones included.
    pub rows: &'a [EpisodeRow],
    /// The frames this process recorded.
    pub kept: &'a Kept,
    /// The run's batches of seeds.
    pub batches: &'a [&'a [u64]],
    /// The run's setup.
    pub setup: &'a Setup<'a>,
    /// The run's world model.
    pub wm: &'a WorldModel,
}

/// Each picked episode's frames: those kept from the run, the others replayed. A replay
/// runs the whole batch the episode ran in: a policy's and a world model's batched
/// calls can round differently with other episodes beside them, so only the same batch
/// gives the run's own frames.
///
/// # Errors
/// A failing replay.
fn frames_of(
    policy: &dyn Policy,
    picks: &[(u64, &'static str)],
    src: &Sources,
) -> Result<Vec<EpisodeFrames>> {
    let name = policy.name();
    let mut replayed: Vec<EpisodeFrames> = Vec::new();
    for &(seed, _) in picks {
        if src.kept.get(name, seed).is_some() || replayed.iter().any(|f| f.seed == seed) {
            continue;
        }
        let batch = src.batches.iter().find(|b| b.contains(&seed)).map_or(vec![seed], |b| b.to_vec());
        tracing::info!(
            "filmstrips: replaying {name}'s batch of {} episodes for seed {seed}, whose frames this run did not keep",
            batch.len()
        );
        // The run's own path (its scheduler, one-thread kernel pools), recording.
        let setup = Setup { record: true, ..*src.setup };
        let job = [Batch { policy: 0, seeds: batch }];
        let mut out = Vec::new();
        let replay =
            |e: EngineError| RunError::Replay { policy: name.to_string(), seed, source: Box::new(e) };
        run_batches::<EngineError>(&[policy], &job, &setup, src.wm, 1, &mut |_, r| {
            out = r?.frames;
            Ok(())
        })
        .map_err(replay)?;
        replayed.extend(out.into_iter().filter(|f| picks.iter().any(|p| p.0 == f.seed)));
    }
    Ok(picks
        .iter()
        .map(|&(seed, _)| {
            src.kept
                .get(name, seed)
                .or_else(|| replayed.iter().find(|f| f.seed == seed))
                .cloned()
                .unwrap_or_default()
        })
        .collect())
}

/// Pads each of `strips` to the longest by repeating its last frame, as one batch of
/// the picked episodes recorded them before recordings ended with their episodes.
fn pad(strips: &mut [&mut Vec<Vec<u8>>]) {
    let longest = strips.iter().map(|s| s.len()).max().unwrap_or(0);
    for s in strips.iter_mut() {
        if let Some(last) = s.last().cloned() {
            s.resize(longest, last);
        }
    }
}

/// The filmstrips show every `EVERY`-th action chunk.
const EVERY: usize = 4;

/// Writes `dir/<policy>_seed<seed>_<tag>.{png,gif}` for the picked seeds, from the
/// frames the run kept or replayed ([`Sources`]); returns the filmstrip paths with captions.
///
/// # Errors
/// A failing replay or an unwritable file.
pub fn write_rollouts(
    dir: &Path,
    policy: &dyn Policy,
    picks: &[(u64, &'static str)],
    src: &Sources,
) -> Result<Vec<(PathBuf, String)>> {
    std::fs::create_dir_all(dir).map_err(RunError::file(format!("creating {}", dir.display())))?;
    if picks.is_empty() {
        return Ok(Vec::new());
    }
    let mut eps = frames_of(policy, picks, src)?;
    pad(&mut eps.iter_mut().map(|e| &mut e.real).collect::<Vec<_>>());
    pad(&mut eps.iter_mut().map(|e| &mut e.imagined).collect::<Vec<_>>());
    let size = src.setup.task.observation_spec().image_size;
    let score = |seed: u64, b: Branch| {
        src.rows
            .iter()
            .find(|r| r.policy == policy.name() && r.seed == seed && r.branch == b)
            .map_or(0.0, |r| r.score)
    };
    let mut out = Vec::new();
    for (&(seed, tag), ep) in picks.iter().zip(&eps) {
        let (r, w) = (&ep.real, &ep.imagined);
        let stem = format!("{}_seed{seed}_{tag}", policy.name());
        let rows =
            vec![r.iter().step_by(EVERY).cloned().collect(), w.iter().step_by(EVERY).cloned().collect()];
        let strip = reports::png::filmstrip(&rows, size, size);
        let png = dir.join(format!("{stem}.png"));
        reports::png::write_png(&png, &strip.pixels, strip.width, strip.height)
            .map_err(|e| RunError::Media(e.to_string()))?;
        let pair: Vec<Vec<u8>> = r.iter().zip(w).map(|(a, b)| side_by_side(a, b, size)).collect();
        let side = u16::try_from(size).unwrap_or(u16::MAX);
        reports::gif::write_gif(&dir.join(format!("{stem}.gif")), &pair, 2 * side, side, 200)
            .map_err(|e| RunError::Media(e.to_string()))?;
        let (rs, ws) = (score(seed, Branch::Sim), score(seed, Branch::WorldModel));
        out.push((
            png,
            format!(
                "{} seed {seed} ({tag} agreement): MuJoCo (top) score {rs:.2}, world model (bottom) score {ws:.2}; every {}th action chunk ({} steps)",
                policy.name(),
                EVERY,
                EVERY * policy.action_horizon()
            ),
        ));
    }
    Ok(out)
}

/// Writes each policy's best- and worst-agreeing episodes as filmstrips into `dir`, from
/// the frames the run kept or replayed ([`Sources`]), the policies (those that loaded, as
/// the run loaded them, with their names) on the pool's threads at once (a policy's
/// replay alone is two episodes: its batched calls leave a core idle), and their
/// `index.json` ([`crate::filmstrips`]); the files and the index are the same in any order.
///
/// # Errors
/// A failing replay or an unwritable file.
pub fn write_filmstrips(
    dir: &Path,
    policies: &[(String, &dyn Policy)],
    src: &Sources,
    pool: &rayon::ThreadPool,
) -> Result<()> {
    use rayon::prelude::*;
    let strips: Vec<Vec<(PathBuf, String)>> = pool.install(|| {
        policies
            .par_iter()
            .map(|(name, policy)| write_rollouts(dir, *policy, &pick_seeds(src.rows, name), src))
            .collect::<Result<_>>()
    })?;
    let index: Vec<crate::filmstrips::Filmstrip> = strips
        .into_iter()
        .flatten()
        .map(|(png, caption)| {
            let png = png.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
            crate::filmstrips::Filmstrip { png, caption }
        })
        .collect();
    std::fs::create_dir_all(dir).map_err(RunError::file(format!("creating {}", dir.display())))?;
    crate::config::write(&dir.join("index.json"), &index)
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
    fn strips_are_padded_with_their_last_frame() {
        let (mut a, mut b, mut c) = (vec![vec![1], vec![2]], vec![vec![5]], Vec::new());
        pad(&mut [&mut a, &mut b, &mut c]);
        assert_eq!((a, b, c), (vec![vec![1], vec![2]], vec![vec![5], vec![5]], Vec::<Vec<u8>>::new()));
    }

    #[test]
    fn side_by_side_interleaves_rows() {
        // 1x1 frames: [a][b] per row.
        assert_eq!(side_by_side(&[1, 2, 3], &[4, 5, 6], 1), vec![1, 2, 3, 4, 5, 6]);
    }
}
