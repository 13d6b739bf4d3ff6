//! Running every policy's batches on `--jobs` worker threads, load-balanced.
//!
//! A batch (one policy, a set of seeds) has two independent tasks: its world-model
//! branch and its MuJoCo branch, each starting from its own copy of the same initial
//! states. The world-model branch is several times the longer (12 episodes × 300
//! steps: 404 s against 93 s), so running the two side by side, batch after batch,
//! left one core idle three quarters of the time. Here the tasks of all batches form
//! one queue — batch 0's world model, batch 0's MuJoCo, batch 1's world model, … —
//! and each worker takes the next one when it is free.
//!
//! Results do not depend on the schedule: every worker runs burn's kernels on its own
//! one-thread rayon pool (floating-point reductions in a fixed order), a task's result
//! is a pure function of its batch, and finished batches are handed on in batch order
//! (a batch waits for the ones before it). A policy whose task fails gets its error
//! reported at that batch; its later batches are dropped (workers skip the ones they
//! have not started), as a sequential run would stop there.

use std::collections::BTreeMap;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;

use harness::policy::Policy;
use harness::results::EpisodeRow;
use world_model::model::WorldModel;

use crate::EngineError;
use crate::imagined::wm_branch;
use crate::sim::sim_branch;
use crate::start::{BranchOut, Setup, Start, Timing};

/// One batch: a policy (index into the loaded policies) and the seeds to run.
pub struct Batch {
    /// Index of the policy.
    pub policy: usize,
    /// Episode seeds.
    pub seeds: Vec<u64>,
}

/// What a finished batch hands on: its rows and, with [`Setup::record`], its frames.
#[derive(Debug, Default)]
pub struct BatchOut {
    /// The rows, MuJoCo and world model alternating, by seed.
    pub rows: Vec<EpisodeRow>,
    /// Each episode's recorded frames, by seed (empty unless [`Setup::record`]).
    pub frames: Vec<EpisodeFrames>,
}

/// One episode's frames at the end of every action chunk it ran, in both branches
/// (the first frame first; [`crate::start::BranchOut::frames`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EpisodeFrames {
    /// Episode seed.
    pub seed: u64,
    /// The MuJoCo branch's frames.
    pub real: Vec<Vec<u8>>,
    /// The world model's frames, as the policy saw them.
    pub imagined: Vec<Vec<u8>>,
}

/// A finished batch, or the policy's error.
pub type BatchResult = Result<BatchOut, EngineError>;

type TaskOut = Option<Result<BranchOut, EngineError>>;

fn run_task(
    policy: &dyn Policy,
    batch: &Batch,
    world: bool,
    s: &Setup,
    wm: &WorldModel,
    t: &mut Timing,
) -> Result<BranchOut, EngineError> {
    let mut start = Start::new(policy.name(), &batch.seeds, s)?;
    start.record = s.record;
    if world { wm_branch(policy, &start, s, wm, t) } else { sim_branch(policy, start, s, t) }
}

/// Runs `batches` on `jobs` workers and calls `done(batch index, result)` on this
/// thread in batch order. Returns the summed timing of all tasks.
///
/// # Errors
/// What `done` returns (e.g. an I/O error writing the rows), or a worker that
/// could not start; a policy's own failure goes to `done`, not here.
pub fn run_batches<E: From<EngineError>>(
    policies: &[&dyn Policy],
    batches: &[Batch],
    s: &Setup,
    wm: &WorldModel,
    jobs: usize,
    done: &mut dyn FnMut(usize, BatchResult) -> Result<(), E>,
) -> Result<Timing, E> {
    let next = AtomicUsize::new(0);
    // Per policy, the first batch that failed: later batches are skipped (never earlier
    // ones, whatever order the workers finish in).
    let failed_at: Vec<AtomicUsize> = policies.iter().map(|_| AtomicUsize::new(usize::MAX)).collect();
    let timing = Mutex::new(Timing::default());
    let (tx, rx) = mpsc::channel::<(usize, TaskOut)>();
    std::thread::scope(|sc| -> Result<(), E> {
        for _ in 0..jobs.max(1).min(2 * batches.len().max(1)) {
            let tx = tx.clone();
            let pool = one_thread_pool()?;
            let (next, failed_at, timing) = (&next, &failed_at, &timing);
            sc.spawn(move || {
                loop {
                    let task = next.fetch_add(1, Ordering::SeqCst);
                    let Some(batch) = batches.get(task / 2) else { break };
                    let out = if task / 2 > failed_at[batch.policy].load(Ordering::SeqCst) {
                        None
                    } else {
                        let mut t = Timing::default();
                        let world = task % 2 == 0;
                        let r =
                            pool.install(|| run_task(policies[batch.policy], batch, world, s, wm, &mut t));
                        if r.is_err() {
                            failed_at[batch.policy].fetch_min(task / 2, Ordering::SeqCst);
                        }
                        if let Ok(mut total) = timing.lock() {
                            total.add(&t);
                        }
                        Some(r)
                    };
                    if tx.send((task, out)).is_err() {
                        break;
                    }
                }
                // The episodes ran on the pool's thread: what it holds for the task goes
                // before it ends (`Task::release_thread`).
                pool.install(|| s.task.release_thread());
            });
        }
        drop(tx);
        // Both halves of each batch, until the batch is complete and all before it are handed on.
        let mut parts: BTreeMap<usize, [Option<TaskOut>; 2]> = BTreeMap::new();
        let mut dead = vec![false; policies.len()];
        let mut handed = 0;
        for (task, out) in rx {
            parts.entry(task / 2).or_default()[task % 2] = Some(out);
            while let Some([Some(_), Some(_)]) = parts.get(&handed) {
                let Some([Some(w), Some(m)]) = parts.remove(&handed) else { break };
                let p = batches[handed].policy;
                if !dead[p] {
                    let result = pair(w, m, policies[p].name(), &batches[handed].seeds);
                    dead[p] = result.is_err();
                    if let Err(e) = done(handed, result) {
                        // The run stops: workers take no further task.
                        next.store(2 * batches.len(), Ordering::SeqCst);
                        return Err(e);
                    }
                }
                handed += 1;
            }
        }
        Ok(())
    })?;
    timing.into_inner().map_err(|_| EngineError::WorkerPanicked.into())
}

/// Runs `work` on each of `items` on `jobs` worker threads and calls `done(index,
/// result)` on this thread in item order (an item waits for the ones before it).
///
/// For work that is not a rank batch (e.g. `simulate --replay-imagined`'s three
/// branches of one checkpoint's seeds). As in [`run_batches`], every worker runs
/// burn's kernels on its own one-thread rayon pool, so a result is a pure function of
/// its item and any worker count hands on the same results.
///
/// `release` runs on each worker's thread when it has no item left, before the thread
/// ends (`Task::release_thread`: what the thread holds for the task's episodes).
///
/// # Errors
/// What `done` returns (workers then take no further item), or a worker that could
/// not start.
pub fn run_ordered<T: Sync, R: Send, E: From<EngineError>>(
    items: &[T],
    jobs: usize,
    work: &(dyn Fn(&T) -> R + Sync),
    release: &(dyn Fn() + Sync),
    done: &mut dyn FnMut(usize, R) -> Result<(), E>,
) -> Result<(), E> {
    let next = AtomicUsize::new(0);
    let (tx, rx) = mpsc::channel::<(usize, R)>();
    std::thread::scope(|sc| -> Result<(), E> {
        for _ in 0..jobs.max(1).min(items.len().max(1)) {
            let tx = tx.clone();
            let pool = one_thread_pool()?;
            let next = &next;
            sc.spawn(move || {
                loop {
                    let i = next.fetch_add(1, Ordering::SeqCst);
                    let Some(item) = items.get(i) else { break };
                    let r = pool.install(|| work(item));
                    if tx.send((i, r)).is_err() {
                        break;
                    }
                }
                pool.install(release);
            });
        }
        drop(tx);
        let mut waiting = BTreeMap::new();
        let mut handed = 0;
        for (i, r) in rx {
            waiting.insert(i, r);
            while let Some(r) = waiting.remove(&handed) {
                if let Err(e) = done(handed, r) {
                    next.store(items.len(), Ordering::SeqCst);
                    return Err(e);
                }
                handed += 1;
            }
        }
        Ok(())
    })
}

/// A rayon pool of one thread, for a worker's kernels.
fn one_thread_pool() -> Result<rayon::ThreadPool, EngineError> {
    rayon::ThreadPoolBuilder::new().num_threads(1).build().map_err(|e| EngineError::Threads(e.to_string()))
}

/// The batch's rows (and frames) from its two halves, or its error (the world model's
/// first). A skipped half only occurs in a batch after one of the policy's that failed,
/// which is never handed on.
fn pair(world: TaskOut, sim: TaskOut, name: &str, seeds: &[u64]) -> BatchResult {
    match (world, sim) {
        (Some(Ok(w)), Some(Ok(m))) => {
            let frames = seeds
                .iter()
                .zip(m.frames.into_iter().zip(w.frames))
                .map(|(&seed, (real, imagined))| EpisodeFrames { seed, real, imagined })
                .collect();
            Ok(BatchOut { rows: m.rows.into_iter().zip(w.rows).flat_map(|(a, b)| [a, b]).collect(), frames })
        }
        (Some(Err(e)), _) | (_, Some(Err(e))) => Err(e),
        _ => Err(EngineError::Skipped { policy: name.to_string() }),
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::Device;
    use harness::policy::{ActionChunk, Observation, PolicyError};
    use harness::results::Branch;
    use harness::rng::Rng;
    use world_model::codec::FrameCodec;
    use world_model::model::WorldModelConfig;
    use world_model::unet::UNetConfig;

    use super::*;

    /// Drives the agent to the centre, or fails on every call.
    struct Fake {
        name: &'static str,
        fail: bool,
    }

    impl Policy for Fake {
        fn name(&self) -> &str {
            self.name
        }
        fn obs_horizon(&self) -> usize {
            2
        }
        fn action_horizon(&self) -> usize {
            4
        }
        fn act(&self, obs: &[Observation], _: &mut [Rng]) -> Result<Vec<ActionChunk>, PolicyError> {
            if self.fail {
                return Err(PolicyError::NonFinite { policy: self.name.into(), episode: 0 });
            }
            Ok(obs.iter().map(|_| vec![vec![256.0, 256.0]; 4]).collect())
        }
    }

    #[test]
    fn any_worker_count_hands_on_the_same_batches_and_stops_a_failing_policy() {
        let task = scenarios::load_task("pusht").unwrap();
        let setup = Setup::new(task.as_ref(), 3, 4, None);
        // A tiny pixel-space world model with random weights: the rows only need to be
        // a deterministic function of the batch.
        let device = Device::flex();
        let size = task.observation_spec().image_size;
        let wm_cfg = WorldModelConfig::pixels(UNetConfig::new(3, 8, vec![1], vec![]).with_groups(4), size);
        let unet = wm_cfg.unet.init(&device);
        let wm = WorldModel::from_parts(wm_cfg, FrameCodec::pixels(size), unet, &device);
        let (good, bad) = (Fake { name: "good", fail: false }, Fake { name: "bad", fail: true });
        let policies: Vec<&dyn Policy> = vec![&good, &bad];
        // Interleaved: good 0, bad 0, good 1, bad 1, good 2, bad 2 (one seed each).
        let batches: Vec<Batch> =
            (0..6).map(|i| Batch { policy: i % 2, seeds: vec![100 + i as u64 / 2] }).collect();
        let run = |jobs: usize| {
            let mut handed = Vec::new();
            run_batches::<EngineError>(&policies, &batches, &setup, &wm, jobs, &mut |j, r| {
                handed.push((
                    j,
                    r.map(|out| serde_json::to_string(&out.rows).unwrap()).map_err(|e| e.to_string()),
                ));
                Ok(())
            })
            .unwrap();
            handed
        };
        let one = run(1);
        // The bad policy fails at its first batch (1) and its later ones (3, 5) are never
        // handed on; the good one's three batches are, in order, two rows per seed.
        let order: Vec<usize> = one.iter().map(|(j, _)| *j).collect();
        assert_eq!(order, vec![0, 1, 2, 4]);
        assert!(one[1].1.as_ref().unwrap_err().contains("policy bad"), "{:?}", one[1]);
        for (_, r) in [&one[0], &one[2], &one[3]] {
            let rows: Vec<EpisodeRow> = serde_json::from_str(r.as_ref().unwrap()).unwrap();
            assert_eq!(rows.len(), 2);
            assert_eq!((rows[0].branch, rows[1].branch), (Branch::Sim, Branch::WorldModel));
        }
        assert_eq!(run(3), one, "three workers hand on exactly what one does");
    }

    #[test]
    fn ordered_work_is_handed_on_in_item_order_on_one_thread_pools_and_stops_at_an_error() {
        // Items 0..6, squared; the later items finish first (they sleep less), yet are
        // handed on in order. Each runs on a pool of one thread.
        let items: Vec<u64> = (0..6).collect();
        let work = |&i: &u64| {
            std::thread::sleep(std::time::Duration::from_millis(5 * (6 - i)));
            (i * i, rayon::current_num_threads())
        };
        for jobs in [1, 3] {
            let mut got = Vec::new();
            run_ordered::<u64, _, EngineError>(&items, jobs, &work, &|| {}, &mut |j, r| {
                got.push((j, r));
                Ok(())
            })
            .unwrap();
            let want: Vec<(usize, (u64, usize))> = (0..6).map(|i| (i, ((i * i) as u64, 1))).collect();
            assert_eq!(got, want, "{jobs} workers");
        }
        // `done` failing at item 2 stops the run with its error; nothing after 2 is handed on.
        let mut seen = Vec::new();
        let err = run_ordered::<u64, _, EngineError>(&items, 2, &work, &|| {}, &mut |j, _| {
            seen.push(j);
            if j == 2 { Err(EngineError::Threads("stop".into())) } else { Ok(()) }
        })
        .unwrap_err();
        assert_eq!(seen, vec![0, 1, 2]);
        assert!(err.to_string().contains("stop"), "{err}");
    }
}
