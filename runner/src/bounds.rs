//! "Bounded, validated values": every count a command takes is checked at parsing
//! against a range that the machine can honour, so that a typo (`--jobs 20000`,
//! `--proposals 1e9`, `--feature-dim 0`) is refused by clap, naming the flag, instead
//! of aborting on memory, spawning without end, or panicking inside burn.

use clap::builder::RangedU64ValueParser;

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
pub fn std_dev(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|_| format!("'{s}' is not a number"))?;
    if v.is_finite() && v >= 0.0 { Ok(v) } else { Err(format!("must be a finite std >= 0, got {s}")) }
}

/// A network width: 1 to [`MAX_WIDTH`].
pub fn width() -> RangedU64ValueParser<usize> {
    count(1, MAX_WIDTH)
}
