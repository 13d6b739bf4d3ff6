//! One module per subcommand (`rank` and `plan`, the largest, are folders); [`run`] dispatches.

pub(crate) mod agreement;
mod collect;
mod collect_policy;
mod dataset;
mod dataset_merge;
mod export_policies;
mod import_judge;
mod import_policy;
mod import_robomimic;
mod import_wm;
mod merge;
pub(crate) mod plan;
pub(crate) mod rank;
mod read_judge;
mod record;
mod scripted;
mod simulate;
mod simulate_policy;
mod simulate_replay;
mod tasks;
mod wm_export;

use std::process::ExitCode;

use anyhow::Result;

use crate::cli::{Cli, Command, DatasetCommand, ImportCommand, TrainCommand, WmCommand};

/// The commit this binary was built from (`+dirty` if tracked files differed from it;
/// "unknown" when built outside a git checkout), recorded by `build.rs`: the
/// provenance every command that writes a model or a score records.
pub(crate) fn git_commit() -> String {
    env!("EVALHARNESS_BUILD_COMMIT").to_string()
}

/// Runs the parsed command; the exit code is 0 unless a gate failed (1).
pub fn run(cli: &Cli) -> Result<ExitCode> {
    match &cli.command {
        Command::Simulate(a) => simulate::run(a, cli.quiet),
        Command::Collect(a) => match &a.policy {
            Some(dir) => collect_policy::run(a, dir, cli.quiet),
            None => collect::run(a, cli.quiet),
        },
        Command::Dataset(DatasetCommand::Info { path, json }) => dataset::info(path, *json),
        Command::Dataset(DatasetCommand::Merge { inputs, out, force }) => {
            dataset_merge::run(inputs, out, *force, cli.quiet)
        }
        Command::Train(t) => {
            stop_on_signals();
            let subcommand = match t {
                TrainCommand::Autoencoder(_) => "autoencoder",
                TrainCommand::WorldModel(_) => "world-model",
                TrainCommand::Policy(_) => "policy",
                TrainCommand::Judge(_) => "judge",
            };
            let inv = trainers::Invocation {
                command_line: crate::stdout::command_line(),
                commit: git_commit(),
                given: crate::cli::given_on_command_line(&["train", subcommand]),
                quiet: cli.quiet,
            };
            trainers::run(t, &inv, &mut |line| outln!("{line}"))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Agreement(a) => agreement::run(a),
        Command::Rank(a) => rank::run(a, cli.render_workers, cli.quiet),
        Command::RankShard { file } => rank::run_shard(file, cli.render_workers, cli.quiet),
        Command::Plan(a) => plan::run(a, cli.quiet),
        Command::Merge(a) => merge::run(&a.shards, &a.out, a.force, a.no_report),
        Command::Tasks(a) => tasks::run(&a.runs, a.tex.as_deref(), a.force),
        // Answered in `main`, before any command runs.
        Command::RenderWorker => Ok(ExitCode::SUCCESS),
        Command::Report(a) => {
            // The report is written into the run's folder: not while a run writes there.
            let _lock = crate::output::lock::lock(&a.out)?;
            let html = runner::report::write_report(&a.out)?;
            outln!("{}", html.display());
            Ok(ExitCode::SUCCESS)
        }
        Command::Wm(WmCommand::Eval(a)) => {
            let out = wm_eval::run(a, &mut |line| outln!("{line}"))?;
            outln!("-> {}", out.display());
            Ok(ExitCode::SUCCESS)
        }
        Command::Wm(WmCommand::Export(a)) => wm_export::run(a),
        Command::Import(ImportCommand::WorldModel(a)) => import_wm::run(a),
        Command::Import(ImportCommand::Judge(a)) => import_judge::run(a),
        Command::Import(ImportCommand::Policy(a)) => import_policy::run(a),
        Command::Scripted(a) => scripted::run(a),
        Command::ExportPolicies(a) => export_policies::run(a),
        Command::ReadJudge(a) => read_judge::run(a),
    }
}

/// Ctrl-C / SIGTERM during training: the first asks the trainer to stop after the
/// step in progress (it saves its checkpoint and provenance; `--resume` continues);
/// a second one exits at once with code 2.
fn stop_on_signals() {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let flag = harness::stop::flag();
    for sig in [SIGINT, SIGTERM] {
        // The conditional shutdown runs first and exits only if the flag is already set.
        let registered = signal_hook::flag::register_conditional_shutdown(sig, 2, flag.clone())
            .and_then(|_| signal_hook::flag::register(sig, flag.clone()));
        if let Err(e) = registered {
            tracing::warn!(signal = sig, error = %e, "cannot catch the signal; an interrupt loses the steps since the last checkpoint");
        }
    }
}
