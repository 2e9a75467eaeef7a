#!/usr/bin/env bash
# Build the ROS interface packages that no wheel provides (control_msgs' FollowJointTrajectory
# subset and tf2_msgs' TFMessage, vendored under ros2_ws/interfaces/) with ament_cmake and
# rosidl_default_generators, and install them into the venv's prefix, where the ROS wheels'
# libraries and Python packages already live (the wheels' bootstrap puts <venv>/lib on the
# library path, so the typesupport libraries are found at run time like the wheels' own).
#
# Skips a package that a sourced system ROS already provides (AMENT_PREFIX_PATH outside the
# venv), and one already built from the same sources (a stamp holds their hash), so re-running
# is cheap. Usage: scripts/build_interfaces.sh [VENV_DIR]   (FORCE=1 rebuilds)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$(cd "${1:-$here/.venv}" && pwd)"
src="$here/ros2_ws/interfaces"
packages=(tf2_msgs control_msgs)
stamps="$venv/share/catheter_interfaces"

provided_by_system_ros() {
  local pkg="$1" prefix
  local IFS=:
  for prefix in ${AMENT_PREFIX_PATH:-}; do
    [ -n "$prefix" ] || continue
    [ "$(cd "$prefix" 2>/dev/null && pwd)" = "$venv" ] && continue
    if [ -e "$prefix/share/ament_index/resource_index/packages/$pkg" ]; then
      echo "$prefix"
      return 0
    fi
  done
  return 1
}

sources_hash() {
  # Everything that shapes the build: the package's own files, the fix-up, this script and the
  # build wheels' pins.
  (cd "$src" && find "$1" cmake requirements-build.txt -type f -print0 | LC_ALL=C sort -z |
    xargs -0 sha256sum; sha256sum "$here/scripts/build_interfaces.sh" | cut -d' ' -f1) |
    sha256sum | cut -d' ' -f1
}

todo=()
for pkg in "${packages[@]}"; do
  if prefix="$(provided_by_system_ros "$pkg")"; then
    echo "interfaces: $pkg comes from $prefix, not built"
  elif [ "${FORCE:-0}" != 1 ] && [ -f "$stamps/$pkg.sha256" ] &&
    [ "$(cat "$stamps/$pkg.sha256")" = "$(sources_hash "$pkg")" ] &&
    [ -e "$venv/share/ament_index/resource_index/packages/$pkg" ]; then
    echo "interfaces: $pkg up to date"
  else
    todo+=("$pkg")
  fi
done
[ ${#todo[@]} -gt 0 ] || exit 0

for tool in cmake make cc c++; do
  if ! command -v "$tool" >/dev/null; then
    echo "interfaces: need '$tool' to build ${todo[*]} (apt-get install cmake build-essential)" >&2
    exit 1
  fi
done
"$venv/bin/python" -m pip --disable-pip-version-check -q install -r "$src/requirements-build.txt"

build_root="$(mktemp -d "${TMPDIR:-/tmp}/catheter-interfaces.XXXXXX")"
trap 'rm -rf "$build_root"' EXIT
# ament's CMake finds generators and typesupports through the ament index of AMENT_PREFIX_PATH.
export AMENT_PREFIX_PATH="$venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export PATH="$venv/bin:$PATH"
mkdir -p "$stamps"
for pkg in "${todo[@]}"; do
  echo "interfaces: building $pkg into $venv"
  start_s=$SECONDS
  log="$build_root/$pkg.log"
  if ! {
    cmake -S "$src/$pkg" -B "$build_root/$pkg" \
      -DCMAKE_INSTALL_PREFIX="$venv" -DCMAKE_PREFIX_PATH="$venv" \
      -DPython3_EXECUTABLE="$venv/bin/python" -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF \
      -DCMAKE_PROJECT_INCLUDE="$src/cmake/wheel_include_dirs_fixup.cmake" &&
      cmake --build "$build_root/$pkg" -j "$(nproc)" &&
      cmake --install "$build_root/$pkg"
  } >"$log" 2>&1; then
    tail -40 "$log" >&2
    echo "interfaces: building $pkg failed (last lines above)" >&2
    exit 1
  fi
  # The manifest lets a person remove what was installed: xargs rm < that file.
  cp "$build_root/$pkg/install_manifest.txt" "$stamps/$pkg.install_manifest.txt"
  sources_hash "$pkg" >"$stamps/$pkg.sha256"
  echo "interfaces: $pkg built in $((SECONDS - start_s)) s"
done
