#!/usr/bin/env bash
# The correlation job, as CI runs it after the tests and as .github/workflows/correlation.yml
# runs it for users: gated `rank` runs with their full reports, then the table of tasks.
#
# By default it ranks the shipped checkpoints of each task that ships them, each into
# $OUT/<task> (OUT defaults to ci-report). Times are on the slower of this workplace's two kinds
# of 2-core machine, with the test build (BENCHMARKS.md, 2026-11-27, "the CI job's time"):
# - Push-T: 7 policies × 30 episodes of the full 300 steps (the default run has 100), gated at
#   Pearson 0.8 and 3 inversions. On three seed ranges no model was chosen on, this size came
#   within 0.1 of the full run's Pearson (BENCHMARKS.md, "Current numbers"). About 7 minutes.
# - Lift: 9 policies × 20 episodes of 150 steps (the default run has 50 episodes), gated at
#   Pearson 0.4 and 12 inversions of 36 pairs (a random order has 18 on average). On three
#   sizing ranges it read Pearson 0.70, 0.56 and 0.79 (5, 8 and 3 inversions), against the
#   50-episode headline's 0.77 and 4. In one process with 2 render workers (the task's
#   rank.toml; see rank_task); about 4 minutes on the faster kind.
# - Can: 9 policies × 20 episodes of 250 steps (the default run has 50), gated at Pearson 0.3
#   and 13 inversions of 36. Sized with the Can world model shipped before the present one: on
#   two sizing ranges it read Pearson 0.45 and 0.77 (9 and 2 inversions), against that model's
#   50-episode headline of 0.71 and 7. With the present model this part read 0.65 with 6
#   inversions on one machine and 0.68 with 7 on the other (its headline: 0.74 and 7). In one
#   process with 2 render workers; it took 14 minutes in 3 shard processes on the slower kind.
#   With Can's adapted models and frames without reflections (2026-12-03): Pearson 0.74 with 6
#   inversions, 5-6 minutes on an Intel Xeon machine (BENCHMARKS.md, 2026-12-04).
# Then `evalharness tasks` writes the side-by-side table ($OUT/tasks.md, $OUT/tasks.tex).
#
# To rank your own checkpoints instead, set SCENARIO (default pusht) and any of POLICIES,
# WORLD_MODEL, JUDGE, EPISODES, MAX_STEPS, MIN_PEARSON and MAX_INVERSIONS: the job then runs
# that one task into $OUT/<scenario>, with the size and gates above for pusht, lift and can unless
# set. PROCESSES sets how many shard processes a run is split into (1: one `rank` process).
#
# It runs $EVALHARNESS if set, else the release binary when there is one (scripts/setup.sh
# builds it), else the test build's (the crates rank runs in are optimised in the test
# profile), else builds one.
# Exit code: 2 if any run failed with an error, else 1 if any gate failed, else 0.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
if [ -n "${EVALHARNESS:-}" ]; then
    bin=$EVALHARNESS
    [ -x "$bin" ] || { echo "correlation.sh: EVALHARNESS=$bin is not an executable file" >&2; exit 2; }
else
    bin=target/release/evalharness
    [ -x "$bin" ] || bin=target/debug/evalharness
    [ -x "$bin" ] || { cargo build --locked; bin=target/debug/evalharness; }
fi
out=${OUT:-ci-report}
case $out in /*) where=$out ;; *) where=$(pwd)/$out ;; esac
status=0
runs=()

# The CI size and gates of a shipped task: episodes, batch, min Pearson, max inversions, processes.
ci_size() {
    case $1 in lift) echo "20 20 0.4 12 1" ;; can) echo "20 20 0.3 13 1" ;; *) echo "30 10 0.8 3 1" ;; esac
}

# once DIR COMMAND...: runs COMMAND --out DIR --force; a run killed by a signal (exit 128 + n;
# a crash inside the system's GL driver, say) has its finished batches saved, so one `--resume`
# completes the same run. Returns the exit code.
once() {
    local dir=$1 rc=0
    shift
    "$@" --out "$dir" --force || rc=$?
    if [ "$rc" -ge 128 ]; then
        echo "correlation.sh: rank $(basename "$dir") ended with exit $rc; resuming it once" >&2
        rc=0
        "$@" --out "$dir" --resume || rc=$?
    fi
    return "$rc"
}

# rank_task TASK EPISODES BATCH MIN_PEARSON MAX_INVERSIONS PROCESSES [extra rank flags...]
#
# PROCESSES > 1 runs `rank --processes`: the run split into that many shard processes, joined
# and finished as one run. With 1 (the default of every task), Lift's and Can's frames are
# rendered by the render workers their rank.toml asks for: one process renders one frame at a
# time (Mesa's llvmpipe crashed with two at once), render worker processes do not share that
# limit. The rows are byte-identical either way (BENCHMARKS.md, 2026-11-27, "the CI job's
# time"; 2026-11-29, "render workers").
rank_task() {
    local task=$1 episodes=$2 batch=$3 min=$4 max=$5 procs=$6
    shift 6
    local name rc=0 started=$SECONDS
    name=$(basename "$task" .toml)
    local dir="$out/$name"
    once "$dir" "$bin" rank --scenario "$task" --episodes "$episodes" --batch "$batch" --bootstrap 1000 \
        --min-pearson "$min" --max-inversions "$max" --processes "$procs" "$@" || rc=$?
    echo "correlation.sh: rank $name: $((SECONDS - started)) s wall in $procs process(es)" >&2
    [ "$rc" -gt "$status" ] && status=$rc
    # A run that ended in an error (2) may have left an earlier run's files: not reported.
    if [ "$rc" -le 1 ] && [ -f "$dir/results.json" ]; then
        runs+=("$dir")
        echo "correlation report ($name): $where/$name/report.html"
    fi
    return 0
}

if [ -n "${SCENARIO:-}${POLICIES:-}${WORLD_MODEL:-}${JUDGE:-}" ]; then
    extra=()
    [ -n "${POLICIES:-}" ] && extra+=(--policies "$POLICIES")
    [ -n "${WORLD_MODEL:-}" ] && extra+=(--world-model "$WORLD_MODEL")
    [ -n "${JUDGE:-}" ] && extra+=(--judge "$JUDGE")
    [ -n "${MAX_STEPS:-}" ] && extra+=(--max-steps "$MAX_STEPS")
    task=${SCENARIO:-pusht}
    read -r episodes batch min max procs <<<"$(ci_size "$task")"
    rank_task "$task" "${EPISODES:-$episodes}" "$batch" "${MIN_PEARSON:-$min}" "${MAX_INVERSIONS:-$max}" \
        "${PROCESSES:-$procs}" ${extra[@]+"${extra[@]}"}
else
    for task in pusht lift can; do
        read -r episodes batch min max procs <<<"$(ci_size "$task")"
        rank_task "$task" "$episodes" "$batch" "$min" "$max" "${PROCESSES:-$procs}"
    done
fi

if [ "${#runs[@]}" -gt 0 ]; then
    "$bin" tasks "${runs[@]}" --tex "$out/tasks.tex" --force | tee "$out/tasks.md"
    echo "task table: $where/tasks.md"
fi
exit "$status"
