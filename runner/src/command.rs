//! What the command crates (`trainers`, `simulation`, `importers`) share around their
//! errors and output: what the binary tells a command of its process ([`Invocation`]), a
//! result line said through a callback ([`say!`](crate::say)), a refusal that names the flag
//! ([`refuse!`](crate::refuse)), and the context a step adds to an error ([`Context`]).
//!
//! Why here: each command crate has its own error enum (its failure domain), and every one
//! of them needs the same two shapes, a refusal and an error in context. [`Contextual`] is
//! those two; the rest is written once against it.

use std::path::{Path, PathBuf};

/// A small JSON file of a command's (`config.json`, `summary.json`, `provenance.json`) that
/// cannot be read or written.
#[derive(Debug, thiserror::Error)]
pub enum JsonFileError {
    /// The file cannot be read.
    #[error("reading {}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file cannot be written.
    #[error("writing {}: {source}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The text is not JSON, or the value cannot be written as JSON.
    #[error("{}: {source}", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// The parser's or encoder's error.
        source: serde_json::Error,
    },
}

/// Reads a JSON file.
///
/// # Errors
/// An unreadable or malformed file, naming it.
pub fn read_json(path: &Path) -> Result<serde_json::Value, JsonFileError> {
    let text = std::fs::read_to_string(path)
        .map_err(|source| JsonFileError::Read { path: path.to_path_buf(), source })?;
    serde_json::from_str(&text).map_err(|source| JsonFileError::Json { path: path.to_path_buf(), source })
}

/// Writes `value` as pretty JSON with a final newline.
///
/// # Errors
/// A value that cannot be encoded, or a file that cannot be written, naming it.
pub fn write_json<T: serde::Serialize + ?Sized>(path: &Path, value: &T) -> Result<(), JsonFileError> {
    let mut text = serde_json::to_string_pretty(value)
        .map_err(|source| JsonFileError::Json { path: path.to_path_buf(), source })?;
    text.push('\n');
    std::fs::write(path, text).map_err(|source| JsonFileError::Write { path: path.to_path_buf(), source })
}

/// What a command knows of the process that runs it, handed over by the binary.
#[derive(Clone, Debug, Default)]
pub struct Invocation {
    /// The process's command line, recorded in sessions and provenance.
    pub command_line: Vec<String>,
    /// The commit the binary was built from, recorded beside it.
    pub commit: String,
    /// The ids of the flags typed on the command line (not defaulted), e.g. `steps`: a
    /// `--resume` refuses those that contradict the saved run.
    pub given: Vec<String>,
    /// No progress bars.
    pub quiet: bool,
}

/// An error enum with a refusal and an error in context.
pub trait Contextual: Sized {
    /// A flag, or a combination of flags and inputs, refused; the message names them.
    fn refused(message: String) -> Self;
    /// `source`, with what the command was doing when it failed.
    fn within(what: String, source: Self) -> Self;
}

/// Returns a refusal ([`Contextual::refused`]) with the formatted message from the function.
#[macro_export]
macro_rules! refuse {
    ($($arg:tt)*) => {
        return Err($crate::command::Contextual::refused(format!($($arg)*)))
    };
}

/// Writes one result line to a command's output (`say`: the binary's stdout).
#[macro_export]
macro_rules! say {
    ($say:expr, $($arg:tt)*) => {
        ($say)(&format!($($arg)*))
    };
}

/// For the error enum `$error`, whose variants `Refused(String)` and
/// `In { what: String, source: Box<Self> }` are a refusal and an error in context: implements
/// [`Contextual`] on them, and defines in the calling module `Context`, the extension that
/// says what a command was doing when an error (or an absent value) stopped it:
/// `with_context(|| ...)` and `context(...)` on any `Result` whose error converts into
/// `$error`, and on `Option` (an absent value is refused with the message).
///
/// A macro rather than one generic trait: the command crate's own error type must be fixed
/// at the call site for `?` to infer it.
#[macro_export]
macro_rules! context_for {
    ($error:ident) => {
        impl $crate::command::Contextual for $error {
            fn refused(message: String) -> Self {
                Self::Refused(message)
            }

            fn within(what: String, source: Self) -> Self {
                Self::In { what, source: Box::new(source) }
            }
        }

        /// Says what the command was doing when an error (or an absent value) stopped it.
        pub trait Context<T> {
            /// The error in context with `what()`; an absent value refused with it.
            ///
            /// # Errors
            /// The wrapped error.
            fn with_context<S: std::fmt::Display>(self, what: impl FnOnce() -> S) -> Result<T, $error>;

            /// As [`Context::with_context`], with `what`.
            ///
            /// # Errors
            /// The wrapped error.
            fn context<S: std::fmt::Display>(self, what: S) -> Result<T, $error>
            where
                Self: Sized,
            {
                self.with_context(|| what)
            }
        }

        impl<T, E0: Into<$error>> Context<T> for std::result::Result<T, E0> {
            fn with_context<S: std::fmt::Display>(self, what: impl FnOnce() -> S) -> Result<T, $error> {
                self.map_err(|e| $crate::command::Contextual::within(what().to_string(), e.into()))
            }
        }

        impl<T> Context<T> for Option<T> {
            fn with_context<S: std::fmt::Display>(self, what: impl FnOnce() -> S) -> Result<T, $error> {
                self.ok_or_else(|| $crate::command::Contextual::refused(what().to_string()))
            }
        }
    };
}

#[cfg(test)]
mod tests {
    crate::context_for!(Failed);

    /// A command's error: a refusal, or one in context.
    #[derive(Debug, thiserror::Error)]
    pub(crate) enum Failed {
        #[error("{0}")]
        Refused(String),
        #[error("{what}")]
        In { what: String, source: Box<Failed> },
        #[error(transparent)]
        Io(#[from] std::io::Error),
    }

    fn refuses(n: u32) -> Result<u32, Failed> {
        if n == 0 {
            crate::refuse!("--steps {n}: must be positive");
        }
        Ok(n)
    }

    #[test]
    fn context_keeps_the_error_as_its_source_and_a_refusal_names_the_flag() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
        let e: Failed = Err::<(), _>(io).context("reading x.json").unwrap_err();
        assert_eq!(e.to_string(), "reading x.json");
        let source = std::error::Error::source(&e).map(ToString::to_string);
        assert_eq!(source.as_deref(), Some("no such file"));
        let none: Failed = None::<u8>.context("--data d: no data/coverage array").unwrap_err();
        assert_eq!(none.to_string(), "--data d: no data/coverage array");
        assert_eq!(refuses(0).unwrap_err().to_string(), "--steps 0: must be positive");
        let mut said = Vec::new();
        crate::say!(|l: &str| said.push(l.to_string()), "step {}/{}", 2, 2);
        assert_eq!(said, ["step 2/2"]);
    }
}
