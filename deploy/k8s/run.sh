#!/usr/bin/env bash
# deploy/k8s/run.sh [TIMEOUT]: runs the sharded rank (rank-job.yaml), waits until every
# index has completed (default timeout 6h), then runs the merge (rank-merge.yaml) and
# waits for it. Uses the current kubectl context and namespace.
set -euo pipefail
timeout=${1:-6h}
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
kubectl apply -f "$here/rank-job.yaml"
kubectl wait --for=condition=complete job/evalharness-rank --timeout="$timeout"
kubectl apply -f "$here/rank-merge.yaml"
kubectl wait --for=condition=complete job/evalharness-merge --timeout=30m
echo "merged: /runs/rank/merged on the evalharness-runs volume"
