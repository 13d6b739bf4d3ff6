#!/usr/bin/env bash
# deploy/slurm/submit.sh SHARDS OUT [rank arguments...]
#
# Queues `evalharness rank` as a Slurm array of SHARDS tasks (rank.sbatch; task i runs
# `--shard i/SHARDS`) and a merge job (merge.sbatch) that starts once every shard has
# succeeded. Example:
#   EVALHARNESS=$PWD/target/release/evalharness POLICIES=$PWD/checkpoints/pusht/policies \
#       WORLD_MODEL=$PWD/checkpoints/pusht/world_model deploy/slurm/submit.sh 8 /scratch/rank
# Paths are read by the compute nodes, so give ones they share (absolute is safest); the
# jobs inherit this environment (POLICIES, WORLD_MODEL, EVALHARNESS).
set -euo pipefail
if [ $# -lt 2 ]; then
    echo "usage: $0 SHARDS OUT [rank arguments...]" >&2
    exit 2
fi
shards=$1
out=$2
shift 2
if ! [[ $shards =~ ^[1-9][0-9]*$ ]]; then
    echo "SHARDS must be a positive integer, got '$shards'" >&2
    exit 2
fi
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
mkdir -p "$out"
array=$(sbatch --parsable --array="0-$((shards - 1))" --export="ALL,OUT=$out" "$here/rank.sbatch" "$@")
array=${array%%;*}
merge=$(sbatch --parsable --dependency="afterok:$array" --export="ALL,OUT=$out,SHARDS=$shards" "$here/merge.sbatch")
echo "rank array $array ($shards shards), merge $merge -> $out/merged"
