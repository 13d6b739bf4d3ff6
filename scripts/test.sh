#!/usr/bin/env bash
# The test command (README.md, .ci/run): installs what the tests need, then runs them.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
scripts/setup.sh --no-build --tests
# Mesa's llvmpipe without helper threads, as the binary sets it (scenarios::init_mujoco): the unit
# tests that render run their own renderers, outside the binary's main.
export LP_NUM_THREADS=${LP_NUM_THREADS:-0}
cargo test --workspace --locked
