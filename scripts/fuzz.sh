#!/usr/bin/env bash
# Mutation fuzzing of the readers of damageable files (zarr store, episodes.jsonl,
# results.json, the agreement CSV): src/fuzz.rs, 15 s per reader, two at a time (30 s on 2 cores).
# Run by .ci/run after the tests; reuses the test build.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
EVALHARNESS_FUZZ_SECONDS="${EVALHARNESS_FUZZ_SECONDS:-15}" \
  cargo test --locked --bin evalharness fuzz:: -- --test-threads 2
