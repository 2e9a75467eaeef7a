#!/usr/bin/env bash
# Run a command beside N busy-loop processes (default 2): a lab PC that is doing other work.
#   scripts/with_cpu_hogs.sh 2 .venv/bin/pytest -m "slow or not slow"
# The hogs run at normal priority, like a browser or a training job, and are killed on exit.
set -euo pipefail
n="${1:?usage: with_cpu_hogs.sh N command...}"
shift
pids=()
cleanup() { kill "${pids[@]}" 2>/dev/null || true; }
trap cleanup EXIT INT TERM
for _ in $(seq "$n"); do
    python3 -c "while True: pass" &
    pids+=("$!")
done
echo "with_cpu_hogs: ${n} busy loops running (pids ${pids[*]})" >&2
"$@"
