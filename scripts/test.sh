#!/usr/bin/env bash
# The test command (README.md, .ci/run): installs what the tests need, then runs them.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
scripts/setup.sh --no-build --tests
# No module of a crate may reach back to one that reaches it (docs/architecture.md).
python3 scripts/module_cycles.py
# Mesa's llvmpipe without helper threads, as the binary sets it (scenarios::init_mujoco): the unit
# tests that render run their own renderers, outside the binary's main.
export LP_NUM_THREADS=${LP_NUM_THREADS:-0}
# cargo-nextest (on this workplace's machines) runs every test binary's tests in one pool, so no
# core waits while a binary's last test finishes, and each test in its own process, so a crash in
# the GL driver fails one test, not its whole binary. Measured on a 2-core machine: 419 and 475 s
# against 466 s for `cargo test`, within that machine's noise (BENCHMARKS.md, 2026-12-01). Its doc
# tests run apart. Without nextest: `cargo test`.
if cargo nextest --version >/dev/null 2>&1; then
  cargo nextest run --workspace --locked
  cargo test --workspace --locked --doc
else
  cargo test --workspace --locked
fi
