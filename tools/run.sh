#!/usr/bin/env bash
# The main job: installs what is missing, builds the release preset, and runs the engine on its
# built-in default. Extra arguments go to the `fastslam` command line instead of the default.
set -euo pipefail
FASTSLAM_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$FASTSLAM_ROOT"
source tools/lib/setup.sh

fastslam_install_packages
fastslam_setup_ccache
mkdir -p build
fastslam_build release

if [ $# -gt 0 ]; then
  exec build/release/tools/fastslam "$@"
fi
# The built-in default: a stress run over 10^5 landmarks with 100 particles (`fastslam run --help`).
# It writes out/run/{metrics.json,trajectory.csv,...} and draws out/run/map.svg (--plot png: map.png).
build/release/tools/fastslam run --out out/run
