#!/usr/bin/env bash
# Idempotent entrypoint for a PiZero run: start it, or continue it.
#
#   train-or-resume.sh RUN_DIR ITERATIONS [RUN_OPTION...] [-- NEW_RUN_OPTION...]
#
# If RUN_DIR/config.json exists, this runs
#     pizero resume RUN_DIR --iterations ITERATIONS RUN_OPTION...
# and otherwise
#     pizero train --run-dir RUN_DIR --iterations ITERATIONS RUN_OPTION... NEW_RUN_OPTION...
#
# RUN_OPTIONs are those both commands take (--workers, --max-workers,
# --cpus-per-worker, --gpus-per-worker, --address, --checkpoint-every,
# --compile-cache, --min-fraction, --no-progress, ...). NEW_RUN_OPTIONs, after
# "--", only matter for a new run (--env, --env-arg, --preset, --population,
# --seed, ...): a resumed run keeps the config frozen in its config.json.
#
# Running it again after any failure (a retried KubeRay RayJob, a re-submitted
# Ray job) continues from the newest checkpoint; running it after the run is
# complete changes nothing. RUN_DIR must be absolute: `ray job submit` runs the
# entrypoint in a temporary working dir, and a relative run dir would vanish
# with it. PIZERO names the pizero executable (default: pizero on PATH).
#
# Example (a RayJob entrypoint; see cluster/README.md):
#   bash cluster/train-or-resume.sh /mnt/pizero/runs/tsp 400 --workers 4 --no-progress -- --env tsp
set -euo pipefail

usage() {
    echo "usage: $(basename "$0") RUN_DIR ITERATIONS [RUN_OPTION...] [-- NEW_RUN_OPTION...]" >&2
    exit 2
}

[[ $# -ge 2 ]] || usage
run_dir=$1
iterations=$2
shift 2

if [[ $run_dir != /* ]]; then
    echo "train-or-resume.sh: RUN_DIR must be an absolute path, got '$run_dir'" >&2
    exit 2
fi
if ! [[ $iterations =~ ^[1-9][0-9]*$ ]]; then
    echo "train-or-resume.sh: ITERATIONS must be a positive integer, got '$iterations'" >&2
    exit 2
fi

run_options=()
new_run_options=()
# (the ${a[@]+"${a[@]}"} form below keeps empty arrays working under set -u in bash < 4.4)
while [[ $# -gt 0 ]]; do
    if [[ $1 == -- ]]; then
        shift
        new_run_options=("$@")
        break
    fi
    run_options+=("$1")
    shift
done

pizero=${PIZERO:-pizero}
if [[ -f $run_dir/config.json ]]; then
    echo "train-or-resume.sh: $run_dir holds a run: resuming it to $iterations iterations" >&2
    exec "$pizero" resume "$run_dir" --iterations "$iterations" ${run_options[@]+"${run_options[@]}"}
fi
echo "train-or-resume.sh: starting a new run in $run_dir ($iterations iterations)" >&2
exec "$pizero" train --run-dir "$run_dir" --iterations "$iterations" ${run_options[@]+"${run_options[@]}"} ${new_run_options[@]+"${new_run_options[@]}"}
