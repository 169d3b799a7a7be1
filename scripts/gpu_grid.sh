#!/usr/bin/env bash
# The experiment's GPU column on one lent GPU machine (no Ray Tune there: the
# offline wheels leave it out): every (env, method) at seed 0, all at once,
# each with its own CPU cores and an equal share of the GPU, for MINUTES of
# training, evaluated every minute on the experiment's 200 episodes. Then one
# archive of every run's metrics.jsonl and config.
#
#   scripts/gpu_grid.sh OUT MINUTES ENVS METHODS [PYTHON]
#   e.g. scripts/gpu_grid.sh "$OUT" 4 tsp,collect pizero,es,alphazero,muzero python3
set -euo pipefail  # a training that fails or times out ends its own job only: `wait` and the archive still run

out=$1 minutes=$2 envs=$3 methods=$4 python=${5:-python3}
IFS=, read -r -a env_list <<<"$envs"
IFS=, read -r -a method_list <<<"$methods"
runs=$((${#env_list[@]} * ${#method_list[@]}))
cores=$(nproc)
cpus=$((cores / runs > 0 ? cores / runs : 1))
gpu_share=${GPU_SHARE:-$(python3 -c "print(round(1 / $runs, 4))")}  # GPU_SHARE=0: a CPU rehearsal
hard_stop=$(python3 -c "print(int($minutes * 60 + 120))")  # start-up, compiles and evaluations are off the budget's clock
export XLA_PYTHON_CLIENT_PREALLOCATE=false RAY_USAGE_STATS_ENABLED=0 PYTHONUNBUFFERED=1
export JAX_PLATFORMS=${JAX_PLATFORMS:-cuda,cpu}
mkdir -p "$out/runs"
for env in "${env_list[@]}"; do
    for method in "${method_list[@]}"; do
        run="$out/runs/$env/$method/seed0"
        mkdir -p "$(dirname "$run")"
        timeout -s TERM "$hard_stop" "$python" -m pizero_ray.cli train --env "$env" --method "$method" --seed 0 \
            --run-dir "$run" --minutes "$minutes" --eval-every-minutes 1 --eval-episodes 200 \
            --workers 1 --cpus-per-worker "$cpus" --gpus-per-worker "$gpu_share" --no-progress \
            >"$out/runs/$env-$method.log" 2>&1 &
    done
done
wait
for log in "$out"/runs/*.log; do echo "== $log"; tail -n 3 "$log"; done
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader >"$out/runs/gpu.txt" 2>/dev/null || true
echo "$runs runs at once, $cpus CPUs and $gpu_share GPU each, $minutes training minutes" >>"$out/runs/gpu.txt"
# One file back: the device tool returns at most 8.
(cd "$out" && tar czf gpu_grid_runs.tgz --exclude=checkpoints --exclude=tensorboard runs && rm -rf runs)
