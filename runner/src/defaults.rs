//! `rank`'s per-task defaults: what a bare `rank --scenario NAME` runs.
//!
//! Each task's shipped models live in `checkpoints/<task>/` (`policies/`,
//! `world_model/`, and `judge/` for a task without a hand-written judge of imagined
//! frames). An optional `checkpoints/<task>/rank.toml` sets the episodes and step
//! limit that the task's recorded numbers were measured with, and how many shard
//! processes a run is split into; without it a run has 100 episodes per policy, the
//! task's own step limit and one process. Flags override every
//! default, and `config.json` records what was resolved.

use std::path::{Path, PathBuf};

use harness::task::Task;
use serde::Deserialize;

use crate::error::RunError;

/// Episodes per policy when neither `--episodes` nor the task's `rank.toml` says.
const EPISODES: usize = 100;

/// `checkpoints/<task>/rank.toml`.
#[derive(Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
struct TaskDefaults {
    /// Episodes per policy.
    episodes: Option<usize>,
    /// Control steps per episode (e.g. shorter than robomimic's 400-step horizon).
    max_steps: Option<usize>,
    /// Shard processes a run is split into (`rank --processes`).
    processes: Option<usize>,
    /// Render worker processes of a one-process run (`--render-workers`).
    render_workers: Option<usize>,
}

/// What the command line asked for (`None`: not given).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Asked {
    /// `--policies`.
    pub policies: Option<PathBuf>,
    /// `--world-model`.
    pub world_model: Option<PathBuf>,
    /// `--judge`.
    pub judge: Option<PathBuf>,
    /// `--episodes`.
    pub episodes: Option<usize>,
    /// `--max-steps`.
    pub max_steps: Option<usize>,
    /// `--processes`.
    pub processes: Option<usize>,
    /// Whether the run is one shard (`--shard`): one process whatever the task's file says.
    pub shard: bool,
    /// The global `--render-workers`.
    pub render_workers: Option<usize>,
}

/// The inputs and sizes of a run, flags first, then the task's defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct Resolved {
    /// Policy checkpoint or folder.
    pub policies: PathBuf,
    /// World model.
    pub world_model: PathBuf,
    /// Learned judge of imagined frames, if any.
    pub judge: Option<PathBuf>,
    /// Episodes per policy.
    pub episodes: usize,
    /// Control steps per episode.
    pub max_steps: usize,
    /// Whether the task's episodes have a hand-written judge of imagined frames.
    pub own_judge: bool,
    /// Processes the run is split into (1 for a `--shard`, which is one process).
    pub processes: usize,
    /// Render worker processes (`--render-workers`, else the task's; 0: frames are
    /// rendered in this process).
    pub render_workers: usize,
}

/// Resolves `a` for `task` from the shipped folder `root/<task>` (`checkpoints`).
///
/// # Errors
/// [`RunError::Io`] for an unreadable `rank.toml`, [`RunError::Defaults`] for an invalid one.
pub fn resolve(a: &Asked, task: &dyn Task, root: &Path) -> Result<Resolved, RunError> {
    let dir = root.join(task.name());
    let file = dir.join("rank.toml");
    let d: TaskDefaults = if file.exists() {
        let text =
            std::fs::read_to_string(&file).map_err(|source| RunError::Io { path: file.clone(), source })?;
        toml::from_str(&text).map_err(|source| RunError::Defaults { path: file.clone(), source })?
    } else {
        TaskDefaults::default()
    };
    let (judge, own_judge) = judge(a.judge.as_deref(), task, root);
    Ok(Resolved {
        policies: a.policies.clone().unwrap_or_else(|| dir.join("policies")),
        world_model: a.world_model.clone().unwrap_or_else(|| dir.join("world_model")),
        judge,
        episodes: a.episodes.or(d.episodes).unwrap_or(EPISODES),
        max_steps: a.max_steps.or(d.max_steps).unwrap_or_else(|| task.max_steps()),
        own_judge,
        processes: a.processes.or(if a.shard { None } else { d.processes }).unwrap_or(1),
        render_workers: a.render_workers.or(d.render_workers).unwrap_or(0),
    })
}

/// The learned judge of imagined frames: `given`, else the shipped `root/<task>/judge`
/// where it exists and the task has no hand-written judge
/// ([`Task::judges_own_frames`], answered without a reset); and whether it has one.
/// Shared by `rank` and `simulate --replay-imagined`.
pub fn judge(given: Option<&Path>, task: &dyn Task, root: &Path) -> (Option<PathBuf>, bool) {
    let shipped = root.join(task.name()).join("judge");
    let own = task.judges_own_frames();
    let judge = given.map(Path::to_path_buf).or_else(|| (!own && shipped.is_dir()).then_some(shipped));
    (judge, own)
}

impl Resolved {
    /// Every input the run lacks, one line each saying how to supply it, so that a
    /// task whose models are not shipped yet is told everything at once.
    pub fn missing(&self, scenario: &str) -> Vec<String> {
        let mut out = Vec::new();
        if !self.policies.exists() {
            out.push(format!("policies: {} does not exist (pass --policies DIR)", self.policies.display()));
        }
        if !self.world_model.is_dir() {
            out.push(format!(
                "world model: {} is not a folder (train one with `evalharness train world-model` \
                 and pass --world-model DIR)",
                self.world_model.display()
            ));
        }
        if self.judge.is_none() && !self.own_judge {
            out.push(format!(
                "judge: the {scenario} task has no hand-written judge of imagined frames; train one on \
                 its frames (`evalharness train judge --data DATASET --label success --out DIR`) and \
                 pass --judge DIR"
            ));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_win_then_the_tasks_file_then_the_fallbacks() {
        let task = scenarios::load_task("pusht").expect("Push-T");
        let tmp = tempfile::tempdir().unwrap();
        // No rank.toml: 100 episodes, Push-T's 300 steps, the shipped folders, no judge
        // (Push-T judges its frames itself, even if a judge folder were shipped).
        std::fs::create_dir_all(tmp.path().join("pusht").join("judge")).unwrap();
        let r = resolve(&Asked::default(), task.as_ref(), tmp.path()).unwrap();
        assert_eq!(
            r,
            Resolved {
                policies: tmp.path().join("pusht/policies"),
                world_model: tmp.path().join("pusht/world_model"),
                judge: None,
                episodes: 100,
                max_steps: 300,
                own_judge: true,
                processes: 1,
                render_workers: 0,
            }
        );
        let toml = "episodes = 50\nmax_steps = 120\nprocesses = 3\n";
        std::fs::write(tmp.path().join("pusht/rank.toml"), toml).unwrap();
        let a = Asked { episodes: Some(7), policies: Some("p".into()), ..Asked::default() };
        let r = resolve(&a, task.as_ref(), tmp.path()).unwrap();
        assert_eq!((r.episodes, r.max_steps, r.policies, r.processes), (7, 120, PathBuf::from("p"), 3));
        // The flag wins; a shard is one process whatever the file says.
        let r =
            resolve(&Asked { processes: Some(2), ..Asked::default() }, task.as_ref(), tmp.path()).unwrap();
        assert_eq!(r.processes, 2);
        let r = resolve(&Asked { shard: true, ..Asked::default() }, task.as_ref(), tmp.path()).unwrap();
        assert_eq!(r.processes, 1);
        std::fs::write(tmp.path().join("pusht/rank.toml"), "episode = 50\n").unwrap();
        let e = resolve(&Asked::default(), task.as_ref(), tmp.path()).unwrap_err().to_string();
        assert!(e.contains("rank.toml: invalid rank defaults") && e.contains("episode"), "{e}");
    }

    #[test]
    fn a_task_without_a_judge_gets_its_shipped_one() {
        let task = scenarios::load_task("lift").expect("robosuite assets (scripts/setup.sh)");
        let tmp = tempfile::tempdir().unwrap();
        let r = resolve(&Asked::default(), task.as_ref(), tmp.path()).unwrap();
        // Lift's own step limit is robomimic's 400; no judge is shipped in this folder.
        assert_eq!((r.judge.clone(), r.max_steps), (None, 400));
        // Nothing is shipped in this folder: all three inputs are named at once.
        let missing = r.missing("lift");
        assert_eq!(missing.len(), 3, "{missing:?}");
        assert!(missing[0].starts_with("policies: ") && missing[0].contains("lift/policies"), "{missing:?}");
        assert!(missing[1].starts_with("world model: ") && missing[2].starts_with("judge: "), "{missing:?}");
        std::fs::create_dir_all(tmp.path().join("lift").join("judge")).unwrap();
        let r = resolve(&Asked::default(), task.as_ref(), tmp.path()).unwrap();
        assert_eq!(r.judge, Some(tmp.path().join("lift/judge")));
        std::fs::create_dir_all(tmp.path().join("lift").join("world_model")).unwrap();
        let r = resolve(&Asked { policies: Some(".".into()), ..Asked::default() }, task.as_ref(), tmp.path())
            .unwrap();
        assert!(r.missing("lift").is_empty());
    }

    #[test]
    fn the_shipped_lift_and_can_defaults_are_fifty_episodes_cut_short_with_two_render_workers() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../checkpoints");
        // checkpoints/<task>/rank.toml: the paper's 50 seeds per policy, episodes cut at 150
        // (Lift) and 250 (Can) steps instead of robomimic's 400, in one process whose frames
        // 2 render workers draw; the global flag overrides it.
        for (name, steps) in [("lift", 150), ("can", 250)] {
            let task = scenarios::load_task(name).expect("robosuite assets (scripts/setup.sh)");
            let r = resolve(&Asked::default(), task.as_ref(), &root).unwrap();
            let want = (50, steps, root.join(name).join("policies"), 1, 2);
            let got = (r.episodes, r.max_steps, r.policies.clone(), r.processes, r.render_workers);
            assert_eq!(got, want, "{name}");
            let r = resolve(&Asked { render_workers: Some(0), ..Asked::default() }, task.as_ref(), &root)
                .unwrap();
            assert_eq!(r.render_workers, 0);
            // Every input `rank --scenario NAME` needs is shipped: policies, world model, judge.
            assert_eq!(r.missing(name), Vec::<String>::new(), "{name}");
        }
    }
}
