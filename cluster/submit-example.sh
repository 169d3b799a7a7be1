#!/usr/bin/env bash
# End to end on the local cluster of cluster/local-cluster.sh: submit a tiny
# TSP training as a Ray job, continue it in a second job and stop that one
# part-way with `ray job stop` (pizero saves a checkpoint on SIGTERM), then
# finish it with a third job. Every step is a command you can paste.
#
#   cluster/local-cluster.sh start
#   cluster/submit-example.sh [RUN_DIR]     # default: runs/cluster-example-<time> in the repo
#   cluster/local-cluster.sh stop
#
# PIZERO_EXAMPLE_TARGET (default 200) and PIZERO_EXAMPLE_STOP_AFTER (15) set
# the total iterations and where the second job is stopped (the tests shorten it).
#
# The run dir must be absolute: a Ray job's entrypoint runs in a temporary
# copy of --working-dir, so a relative path would point into that copy.
set -euo pipefail

# shellcheck source-path=SCRIPTDIR source=local-defaults.sh
source "$(dirname "${BASH_SOURCE[0]}")/local-defaults.sh"

dashboard_host=$PIZERO_DASHBOARD_HOST
[[ $dashboard_host == 0.0.0.0 ]] && dashboard_host=127.0.0.1
address="http://$dashboard_host:$PIZERO_DASHBOARD_PORT"

run_dir=${1:-$PIZERO_REPO/runs/cluster-example-$(date +%Y%m%d-%H%M%S)}
case $run_dir in
    /*) ;;
    *) run_dir="$PWD/$run_dir" ;;  # make it absolute here, before Ray changes the working dir
esac
stamp=$(date +%s)
first_iterations=5                              # the first job trains this far
target=${PIZERO_EXAMPLE_TARGET:-200}            # the second job aims here and is stopped part-way; the third gets there
stop_after=${PIZERO_EXAMPLE_STOP_AFTER:-15}     # stop the second job once this many iterations are done
# A tiny agent (--preset tiny) with a population big enough that an iteration
# takes a moment; the same options for every job.
run_options=(--workers 2 --checkpoint-every 10 --no-progress)

step() { printf '\n=== %s\n' "$*"; }
show() { printf '+ %s\n' "$*"; "$@"; }
last_iteration() {
    python3 -c 'import json, sys
rows = [json.loads(line) for line in open(sys.argv[1]) if line.strip()]
print(max((row["iteration"] for row in rows), default=0))' "$run_dir/metrics.jsonl" 2>/dev/null || echo 0
}

if ! ray job list --address "$address" >/dev/null 2>&1; then
    echo "submit-example.sh: no Ray job API at $address (start one with: cluster/local-cluster.sh start)" >&2
    exit 1
fi

step "1. train: a new run in $run_dir ($first_iterations iterations); ray job submit waits for it"
show ray job submit --address "$address" --working-dir "$PIZERO_REPO" \
    --submission-id "pizero-train-$stamp" -- \
    pizero train --env tsp --preset tiny --population 64 --chunk-size 16 --run-dir "$run_dir" \
    --iterations "$first_iterations" "${run_options[@]}"

step "2. resume towards $target iterations in a second job, then stop it part-way"
# RAY_JOB_STOP_WAIT_TIME_S: how long `ray job stop` waits after SIGTERM before
# SIGKILL (Ray's default is 3 s; pizero's checkpoint takes about 1 s for small
# models, give big ones more).
show ray job submit --address "$address" --working-dir "$PIZERO_REPO" --no-wait \
    --submission-id "pizero-resume-$stamp" \
    --runtime-env-json '{"env_vars": {"RAY_JOB_STOP_WAIT_TIME_S": "30"}}' -- \
    pizero resume "$run_dir" --iterations "$target" "${run_options[@]}"
deadline=$((SECONDS + 600))
next_status=$SECONDS
until [[ $(last_iteration) -ge $stop_after ]]; do
    # Each `ray job status` is a new Python process importing Ray (about 1.7 s of
    # CPU): ask it every few seconds, and read the metrics file in between.
    if [[ $SECONDS -ge $next_status ]]; then
        next_status=$((SECONDS + 3))
        status=$(ray job status --address "$address" "pizero-resume-$stamp" 2>/dev/null | tail -n 1 || true)
        if [[ $status == *SUCCEEDED* || $status == *FAILED* || $status == *STOPPED* ]]; then
            echo "submit-example.sh: the second job ended before it could be stopped: $status" >&2
            ray job logs --address "$address" "pizero-resume-$stamp" | tail -n 20 >&2
            exit 1
        fi
    fi
    if [[ $SECONDS -ge $deadline ]]; then
        echo "submit-example.sh: no progress past iteration $(last_iteration) in 10 minutes" >&2
        exit 1
    fi
    sleep 0.2
done
show ray job stop --address "$address" "pizero-resume-$stamp"
echo "The stopped job's last lines (on SIGTERM pizero saves a checkpoint and exits with 143):"
ray job logs --address "$address" "pizero-resume-$stamp" | tail -n 3
show pizero inspect "$run_dir"

step "3. resume again: the third job continues from that checkpoint to $target iterations"
show ray job submit --address "$address" --working-dir "$PIZERO_REPO" \
    --submission-id "pizero-finish-$stamp" -- \
    pizero resume "$run_dir" --iterations "$target" "${run_options[@]}"
show pizero inspect "$run_dir"
printf '\nDone: %s holds %s iterations.\n' "$run_dir" "$(last_iteration)"
