#!/bin/bash
# Entrypoint of the catheter image: source ROS 2 and the workspace overlay, then become the
# command (exec), so that it receives the stop signal directly.
set -e
# shellcheck disable=SC1090,SC1091
source "/opt/ros/${ROS_DISTRO}/setup.bash"
# shellcheck disable=SC1091
source /ws/install/setup.bash
exec "$@"
