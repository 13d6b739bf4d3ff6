//! Agentview frames rendered by worker processes, so that one process's workers can
//! render at the same time.
//!
//! Mesa's llvmpipe crashed when two threads of one process rendered at once (see
//! [`super::episode`]'s render lock), so within a process frames are rendered one at a
//! time, and a frame is the bulk of a Lift or Can control step's cost. A worker process
//! has its own GL context and its own llvmpipe screen: with a pool of workers, `--jobs`
//! threads render concurrently, each frame in some worker.
//!
//! A frame is the same bytes in a worker as in the process: the worker builds the
//! same compiled model from the same recipe (a [`ModelKey`]: the task, its config and
//! the object's size; compiling is deterministic), is sent the joint positions the
//! episode's kinematics were last computed at (after a step, the positions before the
//! last integration, as MuJoCo leaves them), runs the kinematics on them and renders
//! through the same function. A Lift model is 64 MB, so a recipe, not the model,
//! crosses the pipe, and each worker keeps the models of its thread's batch.
//!
//! Each calling thread is served by one worker (assigned in turn at its first frame),
//! so a worker sees one batch's episodes and keeps their models.
//!
//! The protocol, over the worker's stdin and stdout, little-endian:
//! - `F` len:u32 key:JSON size:u32 nq:u32 qpos:f64×nq — render a `size`² frame;
//! - answer: `K` followed by size²·3 bytes, or `E` len:u32 message.

use std::cell::Cell;
use std::collections::HashMap;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use mujoco_rs::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::ScenarioError;

/// The process-wide pool, once started by the binary ([`start`]).
static POOL: OnceLock<Pool> = OnceLock::new();

/// What a worker needs to build an episode's model: the same recipe gives the same
/// compiled model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelKey {
    /// The task (`lift`, `can`).
    pub task: String,
    /// The task's config, as JSON.
    pub config: String,
    /// The robosuite asset folder.
    pub assets: PathBuf,
    /// The object's half-sizes where the model depends on them (Lift's cube).
    pub object_half: Option<[f64; 3]>,
}

fn err(message: impl Into<String>) -> ScenarioError {
    ScenarioError::Render { message: message.into() }
}

/// One worker process.
struct Worker {
    child: Child,
    /// Requests; `None` once [`stop`] closed them.
    to: Option<BufWriter<ChildStdin>>,
    from: BufReader<ChildStdout>,
}

/// The workers, each behind its own lock, and the next one to assign to a thread.
struct Pool {
    workers: Vec<Mutex<Worker>>,
    next: AtomicUsize,
}

thread_local! {
    /// The worker serving this thread, once assigned.
    static MINE: Cell<Option<usize>> = const { Cell::new(None) };
}

/// Starts `n` render workers, each `exe` run with `args` (the binary's hidden
/// worker command). Frames of every later episode are rendered by them.
///
/// # Errors
/// A pool already started, or a worker that cannot be spawned.
pub fn start(exe: &Path, args: &[&str], n: usize) -> Result<(), ScenarioError> {
    let mut workers = Vec::with_capacity(n);
    for _ in 0..n {
        let mut child = Command::new(exe)
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .map_err(|e| err(format!("starting a render worker ({}): {e}", exe.display())))?;
        let (Some(to), Some(from)) = (child.stdin.take(), child.stdout.take()) else {
            return Err(err("a render worker without pipes"));
        };
        workers.push(Mutex::new(Worker { child, to: Some(BufWriter::new(to)), from: BufReader::new(from) }));
    }
    POOL.set(Pool { workers, next: AtomicUsize::new(0) })
        .map_err(|_| err("the render workers were started twice"))
}

/// Whether frames go to render workers.
pub fn active() -> bool {
    POOL.get().is_some()
}

/// Ends the workers: closes each one's requests (a worker exits at the end of its input)
/// and waits for it, so that none outlives the process and their CPU time is counted as
/// this process's children's (`/usr/bin/time`, `getrusage`). Call once, when no more
/// frames will be asked for; a later frame is an error naming the closed pipe.
///
/// # Errors
/// A worker that could not be waited for, or that exited with a failure.
pub fn stop() -> Result<(), ScenarioError> {
    let Some(pool) = POOL.get() else { return Ok(()) };
    let mut first_err = None;
    for w in &pool.workers {
        let mut w = w.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        let pid = w.child.id();
        if let Some(mut to) = w.to.take() {
            // Whatever is buffered goes out, then dropping the pipe closes it.
            let _ = to.flush();
        }
        match w.child.wait() {
            Ok(status) if status.success() => {}
            Ok(status) => first_err = first_err.or(Some(err(format!("render worker (pid {pid}) {status}")))),
            Err(e) => {
                first_err = first_err.or(Some(err(format!("waiting for render worker (pid {pid}): {e}"))))
            }
        }
    }
    first_err.map_or(Ok(()), Err)
}

impl ModelKey {
    /// The key as a request names it (JSON), made once per episode.
    ///
    /// # Errors
    /// A key that cannot be written as JSON (an asset path that is not UTF-8).
    pub fn text(&self) -> Result<String, ScenarioError> {
        serde_json::to_string(self).map_err(|e| err(format!("render worker request: {e}")))
    }
}

/// Renders a `size`² frame of the model the key `text` ([`ModelKey::text`]) builds, at
/// joint positions `qpos`, in this thread's worker.
///
/// # Errors
/// A worker that failed or died (its message, or the I/O error).
pub fn render(text: &str, qpos: &[f64], size: usize) -> Result<Vec<u8>, ScenarioError> {
    let pool = POOL.get().ok_or_else(|| err("no render workers"))?;
    let i = MINE.with(|m| {
        *m.get().get_or_insert_with(|| {
            let i = pool.next.fetch_add(1, Ordering::Relaxed) % pool.workers.len();
            m.set(Some(i));
            i
        })
    });
    let mut w = pool.workers[i].lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    ask(&mut w, text, qpos, size)
}

/// One request and its answer.
fn ask(w: &mut Worker, key: &str, qpos: &[f64], size: usize) -> Result<Vec<u8>, ScenarioError> {
    let pid = w.child.id();
    let io = |e: std::io::Error| err(format!("render worker (pid {pid}): {e}"));
    let to = w.to.as_mut().ok_or_else(|| err(format!("render worker (pid {pid}) was stopped")))?;
    to.write_all(b"F").map_err(io)?;
    to.write_all(&(key.len() as u32).to_le_bytes()).map_err(io)?;
    to.write_all(key.as_bytes()).map_err(io)?;
    to.write_all(&(size as u32).to_le_bytes()).map_err(io)?;
    to.write_all(&(qpos.len() as u32).to_le_bytes()).map_err(io)?;
    for q in qpos {
        to.write_all(&q.to_le_bytes()).map_err(io)?;
    }
    to.flush().map_err(io)?;
    let mut tag = [0u8; 1];
    w.from.read_exact(&mut tag).map_err(io)?;
    match &tag {
        b"K" => {
            let mut frame = vec![0u8; size * size * 3];
            w.from.read_exact(&mut frame).map_err(io)?;
            Ok(frame)
        }
        _ => {
            let n = read_u32(&mut w.from).map_err(io)? as usize;
            let mut text = vec![0u8; n.min(1 << 16)];
            w.from.read_exact(&mut text).map_err(io)?;
            Err(err(format!("render worker: {}", String::from_utf8_lossy(&text))))
        }
    }
}

fn read_u32(r: &mut impl Read) -> std::io::Result<u32> {
    let mut b = [0u8; 4];
    r.read_exact(&mut b)?;
    Ok(u32::from_le_bytes(b))
}

fn read_u64(r: &mut impl Read) -> std::io::Result<u64> {
    let mut b = [0u8; 8];
    r.read_exact(&mut b)?;
    Ok(u64::from_le_bytes(b))
}

/// Models a worker keeps (a batch's episodes; Lift builds one per episode).
const KEEP: usize = 64;

/// The worker's loop: answers requests on `input` until it closes (see the module
/// docs), building models with `build`. Frames are rendered by the same function as
/// in a process without workers.
///
/// # Errors
/// A malformed request or a broken pipe.
pub fn serve(
    input: impl Read,
    output: impl Write,
    build: &dyn Fn(&ModelKey) -> Result<MjModel, ScenarioError>,
) -> std::io::Result<()> {
    let (mut input, mut output) = (BufReader::new(input), BufWriter::new(output));
    // Models by their key's text, with the request count at their last use.
    let mut held: HashMap<String, (u64, MjData<Arc<MjModel>>)> = HashMap::new();
    let mut clock = 0u64;
    loop {
        let mut tag = [0u8; 1];
        match input.read_exact(&mut tag) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(()),
            Err(e) => return Err(e),
        }
        if &tag != b"F" {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("render worker: unknown request {tag:?}"),
            ));
        }
        let n = read_u32(&mut input)? as usize;
        let mut text = vec![0u8; n];
        input.read_exact(&mut text)?;
        let text = String::from_utf8_lossy(&text).into_owned();
        let size = read_u32(&mut input)? as usize;
        let nq = read_u32(&mut input)? as usize;
        let mut qpos = vec![0f64; nq];
        for q in &mut qpos {
            *q = f64::from_bits(read_u64(&mut input)?);
        }
        clock += 1;
        let frame = frame(&mut held, &text, clock, build, &qpos, size);
        match frame {
            Ok(f) => {
                output.write_all(b"K")?;
                output.write_all(&f)?;
            }
            Err(e) => {
                // The reply crosses the pipe as text, which the caller makes a render error
                // again: a render error's own message, so that it is not wrapped twice.
                let m = match e {
                    ScenarioError::Render { message } => message,
                    other => other.to_string(),
                };
                output.write_all(b"E")?;
                output.write_all(&(m.len() as u32).to_le_bytes())?;
                output.write_all(m.as_bytes())?;
            }
        }
        output.flush()?;
    }
}

/// One frame of the model `text` names, built (and kept) when not held yet.
fn frame(
    held: &mut HashMap<String, (u64, MjData<Arc<MjModel>>)>,
    text: &str,
    clock: u64,
    build: &dyn Fn(&ModelKey) -> Result<MjModel, ScenarioError>,
    qpos: &[f64],
    size: usize,
) -> Result<Vec<u8>, ScenarioError> {
    let err = |message: String| ScenarioError::Render { message };
    if !held.contains_key(text) {
        let key: ModelKey = serde_json::from_str(text).map_err(|e| err(format!("a request's model: {e}")))?;
        let model = build(&key)?;
        if held.len() >= KEEP {
            let oldest = held.iter().min_by_key(|(_, (t, _))| *t).map(|(k, _)| k.clone());
            if let Some(k) = oldest {
                held.remove(&k);
            }
        }
        held.insert(text.to_string(), (clock, MjData::new(Arc::new(model))));
    }
    let Some((used, data)) = held.get_mut(text) else { return Err(err("no model".into())) };
    *used = clock;
    if data.qpos().len() != qpos.len() {
        return Err(err(format!("{} joint positions for a model of {}", qpos.len(), data.qpos().len())));
    }
    data.qpos_mut().copy_from_slice(qpos);
    data.forward();
    super::renderer::render_agentview(data, size)
}
