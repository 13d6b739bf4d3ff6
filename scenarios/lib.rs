//! Reference simulators for evalharness, one module per task.
//!
//! Each scenario owns its MuJoCo model, its seeded reset (a pure function of the
//! seed), its renderer, its exact scoring and its scripted behaviours (expert and
//! exploration) used to collect datasets, and implements the task interface
//! ([`harness::task::Task`]) the paired engine drives, with its scripted behaviours and
//! dataset layout ([`harness::scripted::Scripted`]) the data commands run; [`load_task`]
//! resolves `--scenario` through one table of the tasks (`TASKS`).

pub mod can;
pub mod error;
pub mod lift;
pub mod pusht;
pub mod reach;
pub mod robosuite;

pub use error::ScenarioError;

use std::path::Path;

use harness::task::Task;
use mujoco_rs::prelude::MjModel;
use robosuite::render_pool::ModelKey;
use robosuite::task::RobosuiteTask;

/// Loads a task: `None` for its shipped parameters, or a scenario file.
type Load = fn(Option<&Path>) -> Result<Box<dyn Task>, ScenarioError>;

/// Builds a render worker's model from an episode's recipe.
type RenderModel = fn(&ModelKey) -> Result<MjModel, ScenarioError>;

/// A task of this build: its name, how it loads (its shipped parameters, or a scenario
/// file whose `name` key names it) and, for tasks whose frames render workers draw, how a
/// worker builds the model an episode asks for.
struct Registered {
    /// The name `--scenario` and a scenario file's `name` give.
    name: &'static str,
    /// Loads the task: `None` for its shipped parameters, or a scenario file.
    load: Load,
    /// Builds a render worker's model from an episode's recipe.
    render_model: Option<RenderModel>,
}

/// The tasks this build runs. Adding a task adds its line here (and its folder).
const TASKS: &[Registered] = &[
    Registered { name: "pusht", load: pusht::registered, render_model: None },
    Registered { name: "pusht-gpc", load: pusht::registered_gpc, render_model: None },
    Registered { name: "lift", load: lift::registered, render_model: Some(lift::render_model) },
    Registered { name: "can", load: can::registered, render_model: Some(can::render_model) },
    Registered { name: "reach", load: reach::registered, render_model: None },
];

/// Names of the scenarios this build can simulate.
pub fn scenarios() -> Vec<&'static str> {
    TASKS.iter().map(|t| t.name).collect()
}

/// The task `--scenario` names: a scenario name (`pusht`, `pusht-gpc`, `lift`, `can`: the
/// shipped parameters) or a scenario .toml file, whose `name` key says which task it
/// describes (a file whose name no other task has is read as Push-T's, whose checks then
/// name what is wrong). The only place that maps a scenario to its implementation
/// ([`TASKS`]).
///
/// # Errors
/// An unknown name, an unreadable or invalid file, or a scene MuJoCo refuses.
pub fn load_task(spec: &str) -> Result<Box<dyn Task>, ScenarioError> {
    if let Some(task) = TASKS.iter().find(|t| t.name == spec) {
        return (task.load)(None);
    }
    let path = Path::new(spec);
    if !(spec.ends_with(".toml") || path.exists()) {
        return Err(ScenarioError::UnknownScenario { name: spec.into(), available: scenarios().join(", ") });
    }
    let named = file_names(path)?;
    let task = TASKS.iter().find(|t| Some(t.name) == named.as_deref()).unwrap_or(&TASKS[0]);
    (task.load)(Some(path))
}

/// A dataset's or recipe's recorded configuration of the task named `scenario`, as that task
/// writes one today ([`Task::recorded_parameters`]): what two records are compared as. An
/// unknown task's record as it is.
pub fn recorded_config(scenario: &str, config: &serde_json::Value) -> serde_json::Value {
    match TASKS.iter().find(|t| t.name == scenario).and_then(|t| (t.load)(None).ok()) {
        Some(task) => task.recorded_parameters(config),
        None => config.clone(),
    }
}

/// The `name` a scenario file gives itself, if it parses and has one.
fn file_names(path: &Path) -> Result<Option<String>, ScenarioError> {
    let text =
        std::fs::read_to_string(path).map_err(|source| ScenarioError::Io { path: path.into(), source })?;
    Ok(toml::from_str::<toml::Table>(&text)
        .ok()
        .and_then(|t| t.get("name").and_then(|n| n.as_str().map(str::to_string))))
}

/// A robosuite task of its shipped parameters or of a scenario file, as a [`Task`].
fn arm_task<S: robosuite::arm_sim::ArmScene>(sim: robosuite::arm_sim::ArmSim<S>) -> Box<dyn Task> {
    Box::new(RobosuiteTask::new(sim))
}

/// Prepares the process for MuJoCo; call it once at the start of `main`, before
/// any other thread exists.
///
/// - Routes MuJoCo's warnings and messages to the `log` crate (and so to the
///   program's `tracing` subscriber) instead of MuJoCo's default: printing to the
///   console and appending to `MUJOCO_LOG.TXT` in the working directory.
/// - Sets `LP_NUM_THREADS=0` unless the environment sets it: Mesa's software
///   renderer (llvmpipe, what MuJoCo's offscreen renderer runs on without a GPU)
///   then rasterises in the rendering thread instead of in helper threads of its
///   own. Mesa 22.3's llvmpipe crashed three times in 18 hours of rendering runs on
///   one of this project's machines, each a segmentation fault while it searched a
///   scene's list of referenced resources (`lp_scene_is_resource_referenced`; BENCHMARKS.md,
///   2026-11-27, "the Can headline"). Without helper threads it crashed once more, so
///   the race is (also) between two workers' GL contexts: the robosuite renderer now
///   lets one thread render at a time (`robosuite::episode`'s render lock), and this
///   setting stays as a second guard. The frames are the same bytes either way.
pub fn init_mujoco() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let set_lp_threads = std::env::var_os("LP_NUM_THREADS").is_none();
        // SAFETY: called from `main` before any other thread exists, so no thread
        // uses MuJoCo while its message handler is replaced (mujoco-rs's
        // requirement), and no thread reads the environment while it is changed
        // (`set_var`'s requirement); Mesa reads the variable later, when the first
        // renderer opens its EGL display.
        #[allow(unsafe_code)]
        unsafe {
            mujoco_rs::prelude::install_logging_hook();
            if set_lp_threads {
                std::env::set_var("LP_NUM_THREADS", "0");
            }
        };
    });
}

/// Builds the model a render worker is asked for: the same function, config and
/// assets as the episode that asked, so the same compiled model.
///
/// # Errors
/// A task without render workers, a config that does not parse, or the build's own errors.
pub fn build_arm_model(key: &ModelKey) -> Result<MjModel, ScenarioError> {
    let build = TASKS.iter().find(|t| t.name == key.task).and_then(|t| t.render_model);
    let build = build
        .ok_or_else(|| ScenarioError::Render { message: format!("no arm model for task {}", key.task) })?;
    build(key)
}

/// A render worker's loop on `input` and `output` (`evalharness render-worker`).
///
/// # Errors
/// A malformed request or a broken pipe.
pub fn serve_render_worker(input: impl std::io::Read, output: impl std::io::Write) -> std::io::Result<()> {
    robosuite::render_pool::serve(input, output, &build_arm_model)
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_task_table_loads_every_task_by_name_and_by_file() {
        let dir = tempfile::tempdir().unwrap();
        for name in super::scenarios() {
            let task = super::load_task(name).expect("robosuite assets (scripts/setup.sh)");
            // `pusht-gpc` is Push-T with GPC's parameters: its task is called `pusht`.
            assert_eq!(task.name(), name.trim_end_matches("-gpc"), "{name}");
            let scripted = task.scripted().expect("every shipped task has scripted behaviours");
            assert!(!scripted.behaviours().is_empty(), "{name}");
        }
        // A file names its task; a file whose name no other task has is read as Push-T's,
        // whose errors then name what is missing.
        let lift = dir.path().join("l.toml");
        std::fs::write(&lift, "name = \"lift\"\n").unwrap();
        assert_eq!(super::load_task(lift.to_str().unwrap()).unwrap().name(), "lift");
        let pusht = concat!(env!("CARGO_MANIFEST_DIR"), "/pusht.toml");
        assert_eq!(super::load_task(pusht).unwrap().name(), "pusht");
        let unnamed = dir.path().join("p.toml");
        std::fs::write(&unnamed, "").unwrap();
        let err = super::load_task(unnamed.to_str().unwrap()).err().unwrap().to_string();
        assert!(err.contains("p.toml") && err.contains("missing field `name`"), "{err}");
        let err = super::load_task("pushq").err().unwrap().to_string();
        assert_eq!(err, "unknown scenario 'pushq' (available: pusht, pusht-gpc, lift, can, reach)");
    }

    #[test]
    fn every_task_says_without_a_reset_whether_its_episodes_judge_their_frames() {
        // `rank` asks `judges_own_frames` to pick a learned judge; the episodes' own
        // `judge` must agree with it (Push-T: its frame scorer; Lift and Can: none).
        for (name, own) in
            [("pusht", true), ("pusht-gpc", true), ("lift", false), ("can", false), ("reach", true)]
        {
            let task = super::load_task(name).expect("robosuite assets (scripts/setup.sh)");
            assert_eq!(task.judges_own_frames(), own, "{name}");
            assert_eq!(task.reset(7).unwrap().judge().is_some(), own, "{name}");
        }
    }
}
