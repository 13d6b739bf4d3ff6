//! One module per subcommand (`plan`, the largest, is a folder); [`run`] dispatches.

pub(crate) mod agreement;
mod export_policies;
mod merge;
pub(crate) mod plan;
mod rank;
mod read_judge;
mod scripted;
mod tasks;
mod wm_export;

use std::process::ExitCode;

use anyhow::Result;

use crate::cli::{Cli, Command, TrainCommand, WmCommand};

/// The commit this binary was built from (`+dirty` if tracked files differed from it;
/// "unknown" when built outside a git checkout), recorded by `build.rs`: the
/// provenance every command that writes a model or a score records.
pub(crate) fn git_commit() -> String {
    env!("EVALHARNESS_BUILD_COMMIT").to_string()
}

/// Runs the parsed command; the exit code is 0 unless a gate failed (1).
pub fn run(cli: &Cli) -> Result<ExitCode> {
    match &cli.command {
        Command::Simulate(a) => {
            let all_ran =
                simulation::simulate(a, &invocation(cli, Vec::new()), &mut |line| outln!("{line}"))?;
            Ok(if all_ran { ExitCode::SUCCESS } else { ExitCode::from(1) })
        }
        Command::Collect(a) => {
            simulation::collect(a, &invocation(cli, Vec::new()), &mut |line| outln!("{line}"))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Dataset(d) => {
            simulation::dataset(d, &invocation(cli, Vec::new()), &mut |line| outln!("{line}"))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Train(t) => {
            stop_on_signals();
            let subcommand = match t {
                TrainCommand::Autoencoder(_) => "autoencoder",
                TrainCommand::WorldModel(_) => "world-model",
                TrainCommand::Policy(_) => "policy",
                TrainCommand::Judge(_) => "judge",
                TrainCommand::Adapt(_) => "adapt",
            };
            let inv = invocation(cli, crate::cli::given_on_command_line(&["train", subcommand]));
            trainers::run(t, &inv, &mut |line| outln!("{line}"))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Agreement(a) => agreement::run(a),
        Command::Rank(a) => rank::run(cli, a),
        Command::RankShard { file } => rank::run_shard(cli, file),
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
        Command::Import(i) => {
            let inv = invocation(cli, Vec::new());
            importers::run(i, &inv, &mut |line| outln!("{line}"))?;
            Ok(ExitCode::SUCCESS)
        }
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

/// What a command crate (`trainers`, `simulation`, `importers`) is told of this process:
/// its command line and commit, the flags typed (`given`, for a `--resume`'s checks), and
/// `--quiet`.
fn invocation(cli: &Cli, given: Vec<String>) -> runner::command::Invocation {
    runner::command::Invocation {
        command_line: crate::stdout::command_line(),
        commit: git_commit(),
        given,
        quiet: cli.quiet,
    }
}
