#!/usr/bin/env bash
# roslaunch env-loader for the stage hosts of vehicle.launch: sets up this
# checkout's built workspace (scripts/lib.sh layout) and runs its arguments.
# On a remote host the checkout must be at the same path and built there
# (scripts/setup, then scripts/demo or scripts/test).
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
fm_source release
exec "$@"
