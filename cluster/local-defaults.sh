# shellcheck shell=bash
# Settings of the two-node local cluster, shared by local-cluster.sh and
# submit-example.sh (sourced, not run). Override any of them in the environment.
# The ports differ from Ray's defaults (6379, 8265, 10001, 52365) so that this
# cluster can run beside another Ray instance on the same machine.

: "${PIZERO_RAY_PORT:=6390}"                   # GCS: the address nodes and drivers join (HOST:PORT)
: "${PIZERO_DASHBOARD_PORT:=8275}"             # dashboard and job-submission API
: "${PIZERO_DASHBOARD_HOST:=127.0.0.1}"        # loopback; 0.0.0.0 exposes it to the network (keep token auth on)
: "${PIZERO_NODE_IP:=127.0.0.1}"               # this machine's address as other nodes see it
: "${PIZERO_CLIENT_PORT:=6391}"                # Ray Client server (unused by pizero, but it needs a free port)
: "${PIZERO_HEAD_AGENT_PORT:=6392}"            # dashboard agent HTTP port of the head node
: "${PIZERO_WORKER_AGENT_PORT:=6393}"          # ... and of the second node (two nodes, one machine: two ports)
: "${PIZERO_HEAD_CPUS:=1}"                     # CPUs each node offers to Ray
: "${PIZERO_WORKER_CPUS:=1}"
: "${PIZERO_OBJECT_STORE_BYTES:=134217728}"    # 128 MiB per node: only parameters (KBs to MBs) travel
: "${PIZERO_RAY_TEMP_DIR:=/tmp/pizero-ray-cluster}"  # this cluster's sessions and logs, apart from /tmp/ray

export PIZERO_RAY_PORT PIZERO_DASHBOARD_PORT PIZERO_DASHBOARD_HOST PIZERO_NODE_IP PIZERO_CLIENT_PORT \
    PIZERO_HEAD_AGENT_PORT PIZERO_WORKER_AGENT_PORT PIZERO_HEAD_CPUS PIZERO_WORKER_CPUS \
    PIZERO_OBJECT_STORE_BYTES PIZERO_RAY_TEMP_DIR

# Token authentication stays on: every ray command of these scripts (ray
# start, ray job submit/stop/logs) runs with RAY_AUTH_MODE=token and the token
# in RAY_AUTH_TOKEN, RAY_AUTH_TOKEN_PATH or ~/.ray/auth_token.
export RAY_AUTH_MODE="${RAY_AUTH_MODE:-token}"
export RAY_USAGE_STATS_ENABLED="${RAY_USAGE_STATS_ENABLED:-0}"

# The repository's virtual environment (made by `make`), else whatever is on PATH.
PIZERO_REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [[ -x $PIZERO_REPO/.venv/bin/ray ]]; then
    # Also puts pizero on the PATH of the cluster's processes, so that a job's
    # entrypoint finds it.
    export PATH="$PIZERO_REPO/.venv/bin:$PATH"
fi
export PIZERO_REPO
