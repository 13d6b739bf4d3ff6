#!/usr/bin/env bash
# The correlation job, as CI runs it after the tests and as .github/workflows/correlation.yml
# runs it for users: `rank` with its full report, gated, then the table of tasks.
#
# By default it ranks the shipped Push-T world model and policy set on 30 episodes of the full
# 300 steps (the default run has 100), about 8 minutes on two cores with the test build: on
# three seed ranges that no model was chosen on, its Pearson came within 0.1 of the full run's
# (BENCHMARKS.md, "Current numbers"). Set POLICIES,
# WORLD_MODEL, SCENARIO, EPISODES, MIN_PEARSON and MAX_INVERSIONS to rank your own.
#
# It runs the release binary when there is one (scripts/setup.sh builds it), else the test
# build's (the crates rank runs in are optimised in the test profile), else builds one.
# Exit code: rank's (1 when a gate fails).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bin=target/release/evalharness
[ -x "$bin" ] || bin=target/debug/evalharness
[ -x "$bin" ] || { cargo build --locked; bin=target/debug/evalharness; }
out=${OUT:-ci-report/rank}
args=(rank --scenario "${SCENARIO:-pusht}" --episodes "${EPISODES:-30}" --batch 10 --bootstrap 1000
    --min-pearson "${MIN_PEARSON:-0.8}" --max-inversions "${MAX_INVERSIONS:-3}" --out "$out" --force)
[ -n "${POLICIES:-}" ] && args+=(--policies "$POLICIES")
[ -n "${WORLD_MODEL:-}" ] && args+=(--world-model "$WORLD_MODEL")
status=0
"$bin" "${args[@]}" || status=$?
if [ -f "$out/results.json" ]; then
    "$bin" tasks "$out" --tex "$out/tasks.tex"
    case $out in /*) where=$out ;; *) where=$(pwd)/$out ;; esac
    echo "correlation report: $where/report.html"
fi
exit "$status"
