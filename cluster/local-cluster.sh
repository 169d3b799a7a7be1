#!/usr/bin/env bash
# A two-node Ray cluster on this machine: a head node and a second worker node,
# each with a small, explicit share of CPUs and object-store memory, token
# authentication on, and the dashboard (job-submission API) on 127.0.0.1.
#
#   cluster/local-cluster.sh start    # start both nodes, print how to use them
#   cluster/local-cluster.sh status   # ray status of this cluster
#   cluster/local-cluster.sh stop-second  # remove the second node (as `ray stop` would on its own machine)
#   cluster/local-cluster.sh stop     # stop this cluster's processes only
#
# Settings (ports, CPUs, memory, temp dir) are in cluster/local-defaults.sh and
# can be overridden from the environment, e.g. PIZERO_RAY_PORT=6400. `stop`
# ends only the processes of this cluster (those whose command line names its
# temp dir, PIZERO_RAY_TEMP_DIR, or its GCS port, and their descendants);
# unlike `ray stop`, it leaves any other Ray instance on the machine alone.
set -euo pipefail

# shellcheck source-path=SCRIPTDIR source=local-defaults.sh
source "$(dirname "${BASH_SOURCE[0]}")/local-defaults.sh"

gcs_address="$PIZERO_NODE_IP:$PIZERO_RAY_PORT"
dashboard_url="http://$PIZERO_DASHBOARD_HOST:$PIZERO_DASHBOARD_PORT"
if [[ $PIZERO_DASHBOARD_HOST == 0.0.0.0 ]]; then
    dashboard_url="http://127.0.0.1:$PIZERO_DASHBOARD_PORT"
fi

die() {
    echo "local-cluster.sh: $*" >&2
    exit 1
}

with_descendants() {
    # The PIDs given and all their descendants, one a word.
    local all=() frontier=("$@") next=() pid child
    while [[ ${#frontier[@]} -gt 0 ]]; do
        all+=("${frontier[@]}")
        next=()
        for pid in "${frontier[@]}"; do
            for child in $(pgrep -P "$pid" || true); do
                next+=("$child")
            done
        done
        frontier=(${next[@]+"${next[@]}"})
    done
    echo ${all[@]+"${all[@]}"}
}

cluster_pids() {
    # This cluster's daemons (GCS, raylets, dashboard, monitors) name its temp
    # dir on their command lines, its Ray Client server its GCS port; their
    # descendants (agents, workers, a job's driver) are found through the
    # process tree. Prints the PIDs, one a word.
    # shellcheck disable=SC2046  # one PID per word
    with_descendants $(pgrep -f -- "$PIZERO_RAY_TEMP_DIR/" || true) \
        $(pgrep -f -- "ray\.util\.client\.server --address=[^ ]*:$PIZERO_RAY_PORT " || true)
}

second_node_pids() {
    # The second node's raylet is the one whose dashboard agent listens on
    # PIZERO_WORKER_AGENT_PORT; its agents and workers descend from it. Its
    # log monitor is Ray's own process beside it, named with the same suffix
    # as the raylet's socket (raylet.1, log_monitor.1.out).
    local raylet suffix
    raylet=$(pgrep -f -- "raylet_socket_name=$PIZERO_RAY_TEMP_DIR/.*--listen-port=$PIZERO_WORKER_AGENT_PORT " || true)
    [[ -z $raylet ]] && return 0
    suffix=$(tr '\0' '\n' <"/proc/$raylet/cmdline" | sed -n 's|^--raylet_socket_name=.*/raylet||p')
    # shellcheck disable=SC2046  # one PID per word
    with_descendants "$raylet" $(pgrep -f -- "$PIZERO_RAY_TEMP_DIR/.*/log_monitor$suffix\.out" || true)
}

port_in_use() {
    python3 - "$1" <<'PY'
import socket, sys
s = socket.socket()
s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as servers do: TIME_WAIT leftovers are no clash
try:
    s.bind(("", int(sys.argv[1])))
except OSError:
    sys.exit(0)  # in use
sys.exit(1)
PY
}

ensure_token() {
    if [[ $RAY_AUTH_MODE != token ]]; then
        echo "local-cluster.sh: WARNING: RAY_AUTH_MODE=$RAY_AUTH_MODE: token authentication is OFF;" \
            "anyone who can reach these ports can run code here" >&2
        return
    fi
    if [[ -z ${RAY_AUTH_TOKEN:-} && -z ${RAY_AUTH_TOKEN_PATH:-} ]]; then
        # Reuses ~/.ray/auth_token, or writes a new random one there.
        ray get-auth-token --generate >/dev/null
    fi
}

wait_for_nodes() {
    local want=$1 alive=0
    for _ in $(seq 60); do
        alive=$(ray status --address="$gcs_address" 2>/dev/null | grep -cE '^ +1 node_' || true)
        if [[ $alive -ge $want ]]; then
            return 0
        fi
        sleep 1
    done
    die "only $alive of $want nodes came up; logs: $PIZERO_RAY_TEMP_DIR/session_latest/logs"
}

start() {
    command -v ray >/dev/null || die "ray is not on PATH (run 'make install', or activate your environment)"
    if [[ -n $(cluster_pids) ]]; then
        die "a cluster with temp dir $PIZERO_RAY_TEMP_DIR is already running ('$0 stop' ends it)"
    fi
    local port
    for port in "$PIZERO_RAY_PORT" "$PIZERO_DASHBOARD_PORT" "$PIZERO_CLIENT_PORT" \
        "$PIZERO_HEAD_AGENT_PORT" "$PIZERO_WORKER_AGENT_PORT"; do
        if port_in_use "$port"; then
            die "port $port is in use; choose others (see cluster/local-defaults.sh)"
        fi
    done
    ensure_token

    echo "Starting the head node ($PIZERO_HEAD_CPUS CPU) at $gcs_address ..."
    ray start --head \
        --node-ip-address="$PIZERO_NODE_IP" \
        --port="$PIZERO_RAY_PORT" \
        --ray-client-server-port="$PIZERO_CLIENT_PORT" \
        --dashboard-host="$PIZERO_DASHBOARD_HOST" \
        --dashboard-port="$PIZERO_DASHBOARD_PORT" \
        --dashboard-agent-listen-port="$PIZERO_HEAD_AGENT_PORT" \
        --num-cpus="$PIZERO_HEAD_CPUS" \
        --num-gpus=0 \
        --object-store-memory="$PIZERO_OBJECT_STORE_BYTES" \
        --temp-dir="$PIZERO_RAY_TEMP_DIR" \
        --disable-usage-stats

    echo "Starting a second node ($PIZERO_WORKER_CPUS CPU) ..."
    ray start \
        --address="$gcs_address" \
        --node-ip-address="$PIZERO_NODE_IP" \
        --dashboard-agent-listen-port="$PIZERO_WORKER_AGENT_PORT" \
        --num-cpus="$PIZERO_WORKER_CPUS" \
        --num-gpus=0 \
        --object-store-memory="$PIZERO_OBJECT_STORE_BYTES" \
        --temp-dir="$PIZERO_RAY_TEMP_DIR"

    wait_for_nodes 2
    cat <<MSG

Two-node Ray cluster up (token authentication: $RAY_AUTH_MODE).
  join it (pizero --address, ray start --address):  $gcs_address
  dashboard and job API (ray job submit --address): $dashboard_url

  export RAY_AUTH_MODE=token   # every client of this cluster needs it, and the token
                               # (~/.ray/auth_token here, or RAY_AUTH_TOKEN)
  ray job submit --address $dashboard_url --working-dir "$PIZERO_REPO" -- \\
      pizero train --env tsp --run-dir "$PIZERO_REPO/runs/cluster-tsp" --workers 2 --no-progress
  cluster/submit-example.sh      # a tiny train, stop and resume, end to end
  cluster/local-cluster.sh stop  # stops this cluster only
MSG
}

alive() {
    # The PIDs given that still run (zombies, which only wait to be reaped, do not count).
    local pid state
    for pid in "$@"; do
        state=$(ps -o stat= -p "$pid" 2>/dev/null || true)
        if [[ -n $state && $state != Z* ]]; then
            echo "$pid"
        fi
    done
}

end_processes() {
    # SIGTERM to the PIDs given, up to 15 s for a clean exit (like `ray stop`), then SIGKILL.
    local pids=("$@") left
    kill -TERM "${pids[@]}" 2>/dev/null || true
    for _ in $(seq 30); do
        left=$(alive "${pids[@]}")
        [[ -z $left ]] && break
        sleep 0.5
    done
    if [[ -n $left ]]; then
        # shellcheck disable=SC2086  # one PID per word
        kill -KILL $left 2>/dev/null || true
        for _ in $(seq 20); do
            [[ -z $(alive "${pids[@]}") ]] && break
            sleep 0.25
        done
    fi
    left=$(alive "${pids[@]}")
    if [[ -n $left ]]; then
        die "processes still running: $left"
    fi
}

stop() {
    local pids
    read -r -a pids <<<"$(cluster_pids)"
    if [[ ${#pids[@]} -eq 0 ]]; then
        echo "No cluster with temp dir $PIZERO_RAY_TEMP_DIR is running."
        return 0
    fi
    echo "Stopping the cluster with temp dir $PIZERO_RAY_TEMP_DIR (${#pids[@]} processes) ..."
    end_processes "${pids[@]}"
    echo "Stopped."
}

stop_second() {
    # What `ray stop` does on the second node's own machine: its raylet, its
    # workers and agents end; the head and a run's driver stay.
    local pids
    read -r -a pids <<<"$(second_node_pids)"
    if [[ ${#pids[@]} -eq 0 ]]; then
        die "no second node of the cluster with temp dir $PIZERO_RAY_TEMP_DIR is running"
    fi
    echo "Stopping the second node (${#pids[@]} processes) ..."
    end_processes "${pids[@]}"
    echo "Stopped the second node; the head runs on."
}

status() {
    ray status --address="$gcs_address"
}

case "${1:-}" in
    start) start ;;
    stop) stop ;;
    stop-second) stop_second ;;
    status) status ;;
    *)
        echo "usage: $0 start|status|stop-second|stop" >&2
        exit 2
        ;;
esac
