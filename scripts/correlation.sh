#!/usr/bin/env bash
# The CI correlation job: `rank` on the shipped world model and policy set, small enough for
# a 2-core CI machine (few episodes, short horizon), with its full report. Uses the binary the
# test build just made (no second, release build). Prints where the report is.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bin=target/debug/evalharness
[ -x "$bin" ] || cargo build --locked
out=ci-report/rank
"$bin" rank --episodes 6 --max-steps 48 --batch 6 --bootstrap 500 --out "$out" --force
echo "correlation report: $(pwd)/$out/report.html"
