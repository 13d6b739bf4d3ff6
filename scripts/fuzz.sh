#!/usr/bin/env bash
# Mutation fuzzing of the readers of damageable files (zarr store, episodes.jsonl,
# results.json, the agreement CSV): runner/src/fuzz.rs, 15 s per reader, two at a time (30 s on 2 cores).
# Run by .ci/run after the tests; reuses the test build (the workspace's library tests, as
# nextest built them, filtered to the fuzz cases).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
EVALHARNESS_FUZZ_SECONDS="${EVALHARNESS_FUZZ_SECONDS:-15}" \
  cargo test --locked --workspace --lib fuzz:: -- --test-threads 2
