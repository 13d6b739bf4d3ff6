//! Results to standard output that survive a closed pipe.
//!
//! `evalharness wm eval … | head -3` closes the pipe while the command still has
//! results to print and files to write. `println!` would panic there, and the panic
//! would unwind through the run: a training run's new checkpoints would be dropped
//! and the exit code would no longer say whether a gate failed. Every result line goes
//! through [`out!`] and [`outln!`] instead: once the reader is gone, further output is
//! dropped quietly, the command finishes its files, and its exit code is the one it
//! would have had.

use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};

/// Set once a write found the pipe closed.
static CLOSED: AtomicBool = AtomicBool::new(false);

/// Writes `args` to stdout, dropping them once the reader has gone.
pub fn write(args: std::fmt::Arguments<'_>) {
    if CLOSED.load(Ordering::Relaxed) {
        return;
    }
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(args).and_then(|()| out.flush()) {
        CLOSED.store(true, Ordering::Relaxed);
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            tracing::warn!("standard output: {e}; the rest of the printed results are dropped");
        }
    }
}

/// `print!` to stdout, quiet once the pipe is closed (see the module docs).
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::stdout::write(format_args!($($arg)*))
    };
}

/// `println!` to stdout, quiet once the pipe is closed (see the module docs).
macro_rules! outln {
    () => {
        $crate::stdout::write(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::stdout::write(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// This process's command line as text for `config.json` and provenance files. An
/// argument that is not UTF-8 (a file name in another encoding) is written with its
/// undecodable bytes replaced (`std::env::args` would panic on it).
pub fn command_line() -> Vec<String> {
    std::env::args_os().map(|a| a.to_string_lossy().into_owned()).collect()
}
