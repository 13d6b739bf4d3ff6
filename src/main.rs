//! `evalharness`: rank robot-policy checkpoints offline in a DriftWorld world
//! model, checked against a MuJoCo reference simulator.
//!
//! `main` only wires logging and maps the outcome to an exit code:
//! 0 success, 1 an evaluation ran but a gate failed, 2 an error.

#[macro_use]
mod stdout;
mod cli;
mod commands;
mod output;
use runner::progress;
mod render_workers;
mod scenario;

use std::io::IsTerminal;
use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    init_logging(args.verbose, args.quiet);
    scenarios::init_mujoco();
    if matches!(args.command, cli::Command::RenderWorker) {
        return match scenarios::serve_render_worker(std::io::stdin().lock(), std::io::stdout().lock()) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("error: render worker: {e}");
                ExitCode::from(2)
            }
        };
    }
    if let Some(n) = args.render_workers.filter(|&n| n > 0)
        && let Err(e) = render_workers::start(n)
    {
        eprintln!("error: {}", chain(&e));
        return ExitCode::from(2);
    }
    // Results go through `out!`/`outln!` (`stdout.rs`), which stay quiet once the
    // reader of a pipe is gone: the command finishes and exits as it would have.
    let code = match commands::run(&args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {}", chain(&e));
            ExitCode::from(2)
        }
    };
    render_workers::stop();
    code
}

/// An error and its causes, each said once: an I/O error wrapped by a context that
/// already quotes it (`reading X: No such file…: No such file…`) is not repeated.
fn chain(e: &anyhow::Error) -> String {
    let mut parts: Vec<String> = Vec::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if !parts.last().is_some_and(|p| p.ends_with(&text)) {
            parts.push(text);
        }
    }
    parts.join(": ")
}

/// Logs go to stderr (stdout carries results only); `RUST_LOG` overrides the level.
fn init_logging(verbose: u8, quiet: bool) {
    let level = match (quiet, verbose) {
        (true, _) => "warn",
        (false, 0) => "info",
        (false, 1) => "debug",
        (false, _) => "trace",
    };
    // MuJoCo's own info messages (model compile timings) are noise at the default level.
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(format!("{level},mujoco=warn")));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .with_target(false)
        .init();
}

#[cfg(test)]
mod tests {
    #[test]
    fn an_error_says_each_cause_once() {
        // At 92f9f2b `{e:#}` printed an I/O error twice when its context quoted it.
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "No such file or directory (os error 2)");
        let e = anyhow::Error::new(io).context("reading x.json: No such file or directory (os error 2)");
        assert_eq!(super::chain(&e), "reading x.json: No such file or directory (os error 2)");
        let e = anyhow::anyhow!("disk full").context("writing y");
        assert_eq!(super::chain(&e), "writing y: disk full");
    }
}
