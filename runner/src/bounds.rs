//! "Bounded, validated values": every count a command takes is checked at parsing
//! against a range that the machine can honour, so that a typo (`--jobs 20000`,
//! `--proposals 1e9`, `--feature-dim 0`) is refused by clap, naming the flag, instead
//! of aborting on memory, spawning without end, or panicking inside burn.

use clap::builder::RangedU64ValueParser;

/// A flag's value outside what it takes; the message says what it takes (clap names the
/// flag).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct OutOfRange(String);

/// Worker threads or processes a command may start.
pub const MAX_WORKERS: u64 = 256;
/// `rank --processes`: shard processes at once.
pub const MAX_PROCESSES: u64 = 64;
/// Episodes or samples advanced together in one batch.
pub const MAX_BATCH: u64 = 10_000;
/// A network's width (channels, features).
pub const MAX_WIDTH: u64 = 4096;

/// A count in `lo..=hi`, as `usize`.
pub fn count(lo: u64, hi: u64) -> RangedU64ValueParser<usize> {
    RangedU64ValueParser::<usize>::new().range(lo..=hi)
}

/// `--jobs`: 1 to [`MAX_WORKERS`].
pub fn workers() -> RangedU64ValueParser<usize> {
    count(1, MAX_WORKERS)
}

/// A batch size: 1 to [`MAX_BATCH`].
pub fn batch() -> RangedU64ValueParser<usize> {
    count(1, MAX_BATCH)
}

/// `--max-steps`: at least 1.
pub fn steps() -> RangedU64ValueParser<u32> {
    RangedU64ValueParser::<u32>::new().range(1..=u64::from(u32::MAX))
}

/// A standard deviation (`--noise`): a finite number of at least 0.
///
/// # Errors
/// The text is not a number, or the number is negative, infinite or NaN (clap adds the flag).
pub fn std_dev(s: &str) -> Result<f64, OutOfRange> {
    let v: f64 = s.trim().parse().map_err(|_| OutOfRange(format!("'{s}' is not a number")))?;
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(OutOfRange(format!("must be a finite std >= 0, got {s}")))
    }
}

/// A network width: 1 to [`MAX_WIDTH`].
pub fn width() -> RangedU64ValueParser<usize> {
    count(1, MAX_WIDTH)
}

/// The most bootstrap replicates a command takes: 500x the default, and a bound on
/// the memory the replicates need.
pub const MAX_BOOTSTRAP: usize = 1_000_000;

/// Parses `--bootstrap`: a count from 1 to [`MAX_BOOTSTRAP`].
pub fn bootstrap_replicates(s: &str) -> Result<usize, OutOfRange> {
    let n: usize = s.parse().map_err(|e| OutOfRange(format!("{e}")))?;
    if (1..=MAX_BOOTSTRAP).contains(&n) {
        Ok(n)
    } else {
        Err(OutOfRange(format!("{n} replicates: give 1 to {MAX_BOOTSTRAP}")))
    }
}

/// Parses a correlation threshold (`--min-pearson`): a finite number in [-1, 1]; NaN
/// would compare false and switch the gate off.
pub fn correlation(s: &str) -> Result<f64, OutOfRange> {
    let r: f64 = s.parse().map_err(|e| OutOfRange(format!("{e}")))?;
    if r.is_finite() && (-1.0..=1.0).contains(&r) {
        Ok(r)
    } else {
        Err(OutOfRange(format!("{s} is not a correlation: give a number in [-1, 1]")))
    }
}
