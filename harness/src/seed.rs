//! Deterministic seed derivation.
//!
//! Every random stream in evalharness comes from a `u64` derived with
//! [`derive`] from a master seed and the identity of what it serves (a scenario
//! name, a policy name, an episode seed), never from a thread index or batch
//! position, so 1 and N worker threads produce identical results.

/// One round of splitmix64 (Steele, Lea, Flood 2014): a bijective 64-bit mixer.
pub const fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// FNV-1a hash of a string, used to fold names into seeds (stable across builds).
pub const fn fnv1a(s: &str) -> u64 {
    let bytes = s.as_bytes();
    let mut h: u64 = 0xCBF2_9CE4_8422_2325;
    let mut i = 0;
    while i < bytes.len() {
        h ^= bytes[i] as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01B3);
        i += 1;
    }
    h
}

/// The most episodes per policy one run accepts: far beyond any evaluation (the
/// paper's use 50 to 100), small enough that the per-episode bookkeeping of a run
/// (seeds, rows, progress) is allocated without risk.
pub const MAX_EPISODES: u64 = 10_000_000;

/// A refused `--seed-start` / `--episodes` pair.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SeedRangeError {
    /// No episodes asked for.
    #[error("--episodes must be at least 1")]
    Empty,
    /// More episodes than [`MAX_EPISODES`].
    #[error("--episodes {0} is more than the {MAX_EPISODES} one run takes; split it with --seed-start")]
    TooMany(u64),
    /// The last seed would pass `u64::MAX` and wrap around to the training seeds at 0.
    #[error("--seed-start {start} with --episodes {count} runs past the last seed ({max}); seeds would wrap around to 0", max = u64::MAX)]
    Overflow {
        /// First seed.
        start: u64,
        /// Episodes.
        count: u64,
    },
}

/// The seeds `start, start + 1, …` of `count` episodes, refusing an empty, huge or
/// wrapping range.
///
/// # Errors
/// [`SeedRangeError`] saying which.
pub fn range(start: u64, count: u64) -> Result<std::ops::RangeInclusive<u64>, SeedRangeError> {
    if count == 0 {
        return Err(SeedRangeError::Empty);
    }
    if count > MAX_EPISODES {
        return Err(SeedRangeError::TooMany(count));
    }
    // The last seed is start + count - 1: it must not pass u64::MAX.
    let end = start.checked_add(count - 1).ok_or(SeedRangeError::Overflow { start, count })?;
    Ok(start..=end)
}

/// A seed derived from a master seed and a sequence of parts.
///
/// ```
/// use harness::seed::{derive, fnv1a};
/// let a = derive(7, &[fnv1a("pusht"), 100_000]);
/// assert_eq!(a, derive(7, &[fnv1a("pusht"), 100_000]));
/// assert_ne!(a, derive(7, &[fnv1a("pusht"), 100_001]));
/// ```
pub fn derive(master: u64, parts: &[u64]) -> u64 {
    parts.iter().fold(splitmix64(master), |acc, &p| splitmix64(acc ^ splitmix64(p)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitmix_reference_values() {
        // Reference outputs of splitmix64 seeded with 0 (Vigna's splitmix64.c):
        // the first two outputs of the generator state 0 are these.
        assert_eq!(splitmix64(0), 0xE220_A839_7B1D_CDAF);
        assert_eq!(splitmix64(0x9E37_79B9_7F4A_7C15), 0x6E78_9E6A_A1B9_65F4);
    }

    #[test]
    fn fnv1a_reference_values() {
        // FNV-1a 64 of "" is the offset basis; of "a" is 0xaf63dc4c8601ec8c.
        assert_eq!(fnv1a(""), 0xCBF2_9CE4_8422_2325);
        assert_eq!(fnv1a("a"), 0xAF63_DC4C_8601_EC8C);
    }

    #[test]
    fn order_of_parts_matters() {
        assert_ne!(derive(1, &[2, 3]), derive(1, &[3, 2]));
        assert_ne!(derive(1, &[2]), derive(2, &[2]));
    }

    #[test]
    fn seed_ranges_never_wrap() {
        assert_eq!(range(100_000, 3), Ok(100_000..=100_002));
        // The last seed may be u64::MAX itself, never one past it.
        assert_eq!(range(u64::MAX, 1), Ok(u64::MAX..=u64::MAX));
        assert_eq!(range(u64::MAX, 2), Err(SeedRangeError::Overflow { start: u64::MAX, count: 2 }));
        assert_eq!(range(u64::MAX - 1, 2), Ok(u64::MAX - 1..=u64::MAX));
        assert_eq!(range(0, 0), Err(SeedRangeError::Empty));
        assert_eq!(range(0, 100_000_000_000), Err(SeedRangeError::TooMany(100_000_000_000)));
        assert!(range(u64::MAX, 2).unwrap_err().to_string().contains("wrap around"));
    }
}
