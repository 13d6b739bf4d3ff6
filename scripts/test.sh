#!/usr/bin/env bash
# The test command (README.md, .ci/run): installs what the tests need, then runs them.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
scripts/setup.sh --no-build --tests
cargo test --workspace --locked
