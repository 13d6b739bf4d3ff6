//! What every `collect` shares, Push-T's (`collect.rs`) and the arm tasks' (`collect_arm.rs`):
//! the behaviour mix (`--mix name=weight,…`), each episode's draw from it, and the common part of
//! a dataset's attributes. Its own module so that the two collectors depend on it, not on each
//! other.

use anyhow::{Result, bail};
use harness::replay::attrs::{DatasetAttrs, EpisodeEntry, Source};
use harness::seed::{derive, fnv1a};

/// Parses `name=weight` pairs, naming behaviours with `parse`, into normalised weights.
pub(super) fn parse_mix_with<K>(text: &str, parse: impl Fn(&str) -> Result<K>) -> Result<Vec<(K, f64)>> {
    let mut mix = Vec::new();
    for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let Some((name, w)) = part.split_once('=') else {
            bail!("--mix: '{part}' is not name=weight");
        };
        let kind = parse(name.trim()).map_err(|e| anyhow::anyhow!("--mix: {e}"))?;
        let w: f64 =
            w.trim().parse().map_err(|_| anyhow::anyhow!("--mix: weight '{w}' of {name} is not a number"))?;
        if !(w.is_finite() && w >= 0.0) {
            bail!("--mix: weight of {name} must be >= 0, got {w}");
        }
        mix.push((kind, w));
    }
    let total: f64 = mix.iter().map(|(_, w)| w).sum();
    if total <= 0.0 {
        bail!("--mix: needs at least one positive weight, got '{text}'");
    }
    Ok(mix.into_iter().map(|(k, w)| (k, w / total)).collect())
}

/// The behaviour of episode `seed`: a pure function of the seed and the mix.
pub(super) fn draw<K: Copy>(mix: &[(K, f64)], seed: u64) -> K {
    let u = (derive(seed, &[fnv1a("collect/mix")]) >> 11) as f64 / (1u64 << 53) as f64;
    let mut acc = 0.0;
    for &(k, w) in mix {
        acc += w;
        if u < acc {
            return k;
        }
    }
    mix.last().map(|m| m.0).expect("a parsed mix has an entry")
}

/// A dataset's attributes from its task's own (`header`): the first seed, how the episodes
/// were made (`source`), the step limit and one entry per episode.
pub(super) fn with_source(
    header: DatasetAttrs,
    seed_start: u64,
    source: Source,
    max_steps: usize,
    episodes: Vec<EpisodeEntry>,
) -> DatasetAttrs {
    DatasetAttrs {
        seed_start: Some(seed_start),
        source,
        max_steps: Some(max_steps as u64),
        episodes,
        ..header
    }
}
