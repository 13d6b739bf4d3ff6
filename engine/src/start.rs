//! What a batch of paired episodes starts from and what a branch returns: the
//! task's episodes reset to the seeds, their judges and first observations, the
//! per-episode policy noise streams; the timing split; a branch's rows, filmstrip
//! frames and (for `collect --policy`) whole trajectories; and each episode's
//! running score and when it ends. The branches are in [`crate::sim`] and
//! [`crate::imagined`].

use std::collections::VecDeque;

use harness::judge::{Judge, Replaced, SceneCheck, Sustained};
use harness::policy::{Observation, Policy};
use harness::rng::Rng;
use harness::seed::{derive, fnv1a};
use harness::task::{Env, ScoreKind, Seen, Task};

use crate::EngineError;
use harness::results::EpisodeRow;

/// Wall-clock split of a batch.
#[derive(Clone, Copy, Debug, Default)]
pub struct Timing {
    /// Simulator stepping and rendering.
    pub sim_s: f64,
    /// World-model prediction and decoding.
    pub world_model_s: f64,
    /// Policy inference (both branches).
    pub policy_s: f64,
    /// Frames the world model generated.
    pub frames: u64,
}

impl Timing {
    /// Adds another split.
    pub fn add(&mut self, o: &Timing) {
        self.sim_s += o.sim_s;
        self.world_model_s += o.world_model_s;
        self.policy_s += o.policy_s;
        self.frames += o.frames;
    }
}

/// What a rollout needs besides the policy.
#[derive(Clone, Copy)]
pub struct Setup<'a> {
    /// The task.
    pub task: &'a dyn Task,
    /// Master seed of the policy noise.
    pub master_seed: u64,
    /// Control steps per episode.
    pub max_steps: usize,
    /// A judge of every episode's frames in place of the task's (`rank --judge`);
    /// the task's judge still makes the scene checks.
    pub judge: Option<&'a std::sync::Arc<dyn Judge>>,
    /// World-model branch: judge every generated frame (the official DriftWorld loop), not
    /// only the frames the policy sees.
    pub judge_every_frame: bool,
    /// World-model branch: hand policies each generated frame's values before rounding to
    /// bytes as well ([`harness::task::Seen::exact`]; the official loop feeds floats).
    pub float_frames: bool,
    /// Keep each episode's frames at the end of every action chunk in both branches
    /// ([`Start::record`]), handed on with a batch's rows ([`crate::schedule::BatchOut`]):
    /// `rank` takes its filmstrips from the run instead of replaying them.
    pub record: bool,
}

impl<'a> Setup<'a> {
    /// `task`'s episodes with policy noise from `master_seed`, `max_steps` long, judged by
    /// `judge` (else the task's own), the world-model branch judging the frames the policy sees.
    pub fn new(
        task: &'a dyn Task,
        master_seed: u64,
        max_steps: usize,
        judge: Option<&'a std::sync::Arc<dyn Judge>>,
    ) -> Self {
        Self {
            task,
            master_seed,
            max_steps,
            judge,
            judge_every_frame: false,
            float_frames: false,
            record: false,
        }
    }
}

/// What both branches start from: episodes reset to the seeds, their judges, the
/// first observations and the policy noise streams.
pub struct Start {
    pub(crate) envs: Vec<Box<dyn Env>>,
    /// Each episode's judge of frames; `None` for a task without one when none was
    /// given (the simulator branch runs, scoring exactly; the world-model branch refuses).
    pub(crate) judges: Vec<Option<Box<dyn Judge>>>,
    pub(crate) first: Vec<Seen>,
    /// Each episode's goal pose at reset (for recorded trajectories).
    pub(crate) goals: Vec<Option<[f64; 3]>>,
    /// Each episode's named conditions at reset ([`Env::conditions`], for the rows of both
    /// branches).
    pub(crate) conditions: Vec<Vec<(&'static str, f64)>>,
    pub(crate) policy_rngs: Vec<Rng>,
    pub(crate) seeds: Vec<u64>,
    /// Keep the last frame of every action chunk (for filmstrips and GIFs).
    pub record: bool,
    /// Keep every episode's trajectory: in the simulator branch every step's
    /// observation, state, action and raw score (`collect --policy`); in the
    /// world-model branch the executed actions only (`simulate --replay-imagined`).
    pub trajectories: bool,
    /// Simulator branch only: keep stepping after success, up to the step limit
    /// (`collect --policy --no-early-stop`, so that success lasts in the data).
    pub run_on: bool,
    /// Simulator branch only: rewrites every frame before the policy sees it, the first
    /// ones included (`simulate --observe-through`: a world model's autoencoder
    /// rendering of the real frame), so that a policy's behaviour on rendered frames is
    /// measured with exact scores. The judge and the scene checks read the real frames.
    pub observe: Option<Observe>,
}

/// Rewrites a batch of HWC frames in place ([`Start::observe`]).
pub type Observe = std::sync::Arc<dyn Fn(&mut [Vec<u8>]) + Send + Sync>;

/// One recorded episode, step by step (from the world-model branch: its seed, actions,
/// score and success only).
#[derive(Clone, Debug, Default)]
pub struct Trajectory {
    /// Episode seed.
    pub seed: u64,
    /// The observation frame before each action, then the final one.
    pub frames: Vec<Vec<u8>>,
    /// The privileged state before each action ([`Env::state`]).
    pub states: Vec<Vec<f64>>,
    /// The executed actions.
    pub actions: Vec<Vec<f32>>,
    /// The exact raw score after each action.
    pub raw: Vec<f64>,
    /// The goal pose, where the task has one.
    pub goal: Option<[f64; 3]>,
    /// The episode's score (best reward).
    pub score: f64,
    /// Whether the raw score passed the success threshold.
    pub success: bool,
}

/// A branch's rows and, when recording, each episode's frames at the end of every
/// action chunk it ran (the first frame first; an episode that ended early has fewer).
pub struct BranchOut {
    /// One row per episode.
    pub rows: Vec<EpisodeRow>,
    /// Recorded frames per episode (empty unless recording), each up to its episode's end.
    pub frames: Vec<Vec<Vec<u8>>>,
    /// Whole episodes (empty unless [`Start::trajectories`]; from the world-model
    /// branch, the seeds, actions, scores and successes only).
    pub episodes: Vec<Trajectory>,
}

impl Start {
    /// Resets one episode per seed, each with its judge of frames: the given one, else
    /// the task's own, else none.
    ///
    /// # Errors
    /// A seed whose reset fails, naming it.
    pub fn new(policy: &str, seeds: &[u64], s: &Setup) -> Result<Self, EngineError> {
        let mut envs = Vec::with_capacity(seeds.len());
        for &seed in seeds {
            envs.push(s.task.reset(seed)?);
        }
        let judges = envs
            .iter()
            .map(|e| match (s.judge, e.judge()) {
                (Some(j), checks) => Some(Box::new(Replaced { scorer: j.clone(), checks }) as Box<dyn Judge>),
                (None, own) => own,
            })
            .collect();
        Ok(Self {
            judges,
            first: envs.iter().map(|e| e.observe()).collect(),
            goals: envs.iter().map(|e| e.goal_pose()).collect(),
            conditions: envs.iter().map(|e| e.conditions()).collect(),
            policy_rngs: seeds
                .iter()
                .map(|&sd| Rng::new(derive(s.master_seed, &[fnv1a(policy), sd])))
                .collect(),
            seeds: seeds.to_vec(),
            record: false,
            trajectories: false,
            run_on: false,
            observe: None,
            envs,
        })
    }

    /// What both branches set up alike for `policy`.
    pub(crate) fn begin(&self, policy: &dyn Policy, s: &Setup) -> Begin {
        let o = policy.obs_horizon().max(1);
        Begin {
            name: policy.name().to_string(),
            n: self.envs.len(),
            size: s.task.observation_spec().image_size,
            kind: s.task.score_kind(),
            o,
            hist: self.histories(o),
            rngs: self.policy_rngs.clone(),
            track: vec![Track::default(); self.envs.len()],
            rec: self.recording(),
        }
    }

    fn recording(&self) -> Vec<Vec<Vec<u8>>> {
        if self.record { self.first.iter().map(|f| vec![f.frame.clone()]).collect() } else { Vec::new() }
    }

    fn histories(&self, o: usize) -> Vec<VecDeque<Seen>> {
        self.first.iter().map(|f| (0..o).map(|_| f.clone()).collect()).collect()
    }
}

/// A branch's starting state ([`Start::begin`]).
pub(crate) struct Begin {
    /// The policy's name.
    pub(crate) name: String,
    /// Episodes in the batch.
    pub(crate) n: usize,
    /// Frame side in pixels.
    pub(crate) size: usize,
    /// How the task scores.
    pub(crate) kind: ScoreKind,
    /// Observations the policy reads per decision.
    pub(crate) o: usize,
    /// Each episode's last `o` observations (the first one repeated at the start).
    pub(crate) hist: Vec<VecDeque<Seen>>,
    /// Each episode's policy noise stream.
    pub(crate) rngs: Vec<Rng>,
    /// Each episode's running score.
    pub(crate) track: Vec<Track>,
    /// Recorded frames (empty unless recording).
    pub(crate) rec: Vec<Vec<Vec<u8>>>,
}

/// The observation of an episode's last frames and proprioceptive vectors (oldest first).
pub fn obs_of(hist: &VecDeque<Seen>, size: usize) -> Observation {
    Observation {
        frames: hist.iter().map(|s| s.frame.clone()).collect(),
        proprio: hist.iter().map(|s| s.proprio.clone()).collect(),
        robot: hist.iter().map(|s| s.robot.clone()).collect(),
        size,
        // Where any frame has its unrounded values, every frame does: a real frame's are its
        // bytes / 255.
        exact: hist.iter().any(|s| s.exact.is_some()).then(|| {
            hist.iter()
                .map(|s| {
                    s.exact.clone().unwrap_or_else(|| s.frame.iter().map(|&b| f32::from(b) / 255.0).collect())
                })
                .collect()
        }),
        // Where every frame has the camera's own, the observation carries them.
        native: hist.iter().map(|s| s.native.clone()).collect(),
    }
}

/// Appends `item` and keeps the newest `keep` items.
pub fn push<T>(hist: &mut VecDeque<T>, item: T, keep: usize) {
    hist.push_back(item);
    while hist.len() > keep {
        hist.pop_front();
    }
}

/// Per-episode running score.
#[derive(Clone, Debug, Default)]
pub(crate) struct Track {
    pub(crate) best_reward: f64,
    pub(crate) max_raw: f64,
    pub(crate) last_raw: f64,
    /// Control steps executed (until success or the step limit).
    pub(crate) steps: usize,
    /// Score so far at the end of each action chunk (repeated after the episode ended,
    /// so every trace of a batch has the same length).
    pub(crate) trace: Vec<f64>,
    /// Scene checks of the last frame the policy saw.
    pub(crate) scene: Option<SceneCheck>,
    /// The judge's persistence rule (imagined branch, k > 1): scores and the best
    /// reward count a value only once it held for k judged frames in a row.
    pub(crate) sustained: Option<Sustained>,
}

impl Track {
    /// Persistence `k` for a judged episode (`k <= 1`: every value counts alone).
    pub(crate) fn persist(&mut self, k: usize) {
        self.sustained = (k > 1).then(|| Sustained::new(k));
    }

    pub(crate) fn add(&mut self, raw: f64, kind: &ScoreKind) {
        self.last_raw = raw;
        let held = match &mut self.sustained {
            None => raw,
            Some(s) => match s.push(raw) {
                Some(v) => v,
                None => return,
            },
        };
        self.best_reward = self.best_reward.max(kind.reward(held));
        self.max_raw = self.max_raw.max(held);
    }

    pub(crate) fn end_chunk(&mut self) {
        self.trace.push((self.best_reward * 1e6).round() / 1e6);
    }

    /// The episode's row (scores, steps, trace and scene checks; the branch adds the named state).
    pub(crate) fn row(
        &self,
        policy: &str,
        seed: u64,
        branch: harness::results::Branch,
        kind: &ScoreKind,
    ) -> EpisodeRow {
        EpisodeRow::new(
            policy,
            seed,
            branch,
            self.best_reward,
            self.max_raw,
            self.last_raw,
            kind.threshold(),
            self.steps,
        )
        .with_trace(self.trace.clone())
        .with_scene(self.scene.as_ref())
    }
}

/// Episodes still running: gym-pusht ends an episode at success, and so does each
/// branch here, at the end of the action chunk that reached it (its score, the best
/// reward so far, cannot change after that).
pub(crate) fn still_active(active: &[usize], track: &[Track]) -> Vec<usize> {
    active.iter().copied().filter(|&i| track[i].best_reward < 1.0).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn succeeded_episodes_leave_the_batch_and_keep_their_trace() {
        let mut track = vec![Track::default(); 3];
        let kind = ScoreKind::Coverage { success_at: 0.95 };
        // Success coverage 0.95: coverage 0.95 gives reward 1 (ends), 0.5 gives 0.526.
        track[0].add(0.5, &kind);
        track[1].add(0.95, &kind);
        track[2].add(0.2, &kind);
        assert_eq!(still_active(&[0, 1, 2], &track), vec![0, 2]);
        // A finished episode is not revived, and its trace keeps the batch's length.
        assert_eq!(still_active(&[0, 2], &track), vec![0, 2]);
        track.iter_mut().for_each(Track::end_chunk);
        track.iter_mut().for_each(Track::end_chunk);
        assert_eq!(track[1].trace, vec![1.0, 1.0]);
        assert_eq!(track[0].trace, vec![0.526316, 0.526316]);
    }

    #[test]
    fn a_persistent_judge_needs_k_successes_in_a_row() {
        let kind = ScoreKind::Success;
        // k = 2 over 0.9, 0.1, 0.9, 0.1: no two frames in a row above 0.5, so no success,
        // and the highest held value is min(0.9, 0.1) = 0.1; the last raw value is 0.1.
        let mut t = Track::default();
        t.persist(2);
        [0.9, 0.1, 0.9, 0.1].into_iter().for_each(|r| t.add(r, &kind));
        assert_eq!((t.best_reward, t.max_raw, t.last_raw), (0.0, 0.1, 0.1));
        // Then 0.8, 0.7: held min(0.8, 0.7) = 0.7 > 0.5, a success.
        [0.8, 0.7].into_iter().for_each(|r| t.add(r, &kind));
        assert_eq!((t.best_reward, t.max_raw), (1.0, 0.7));
        // k = 1 counts the first 0.9 alone.
        let mut t = Track::default();
        t.persist(1);
        t.add(0.9, &kind);
        assert_eq!((t.best_reward, t.max_raw), (1.0, 0.9));
    }

    #[test]
    fn observations_carry_the_proprioception_of_any_size() {
        let seen = |p: Vec<f32>| Seen {
            frame: vec![0; 3],
            proprio: p,
            robot: Vec::new(),
            exact: None,
            native: None,
        };
        let hist: VecDeque<Seen> = [seen(vec![1.0, 2.0]), seen(vec![3.0, 4.0])].into();
        let obs = obs_of(&hist, 1);
        assert_eq!(obs.proprio, vec![vec![1.0, 2.0], vec![3.0, 4.0]]);
        assert_eq!(obs.frames.len(), 2);
        let lift: VecDeque<Seen> = [seen(vec![0.5; 9])].into();
        assert_eq!(obs_of(&lift, 1).proprio, vec![vec![0.5; 9]]);
    }
}
