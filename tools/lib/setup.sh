# Shared by tools/run.sh and tools/test.sh (sourced, not run): installs the Debian packages the
# build needs when any is missing (apt-get as root, sudo otherwise; nothing when all are there;
# clang-14 and libclang-rt-14-dev are the fuzz preset's compiler and libFuzzer; Open MPI is
# `fastslam sweep`'s optional spreading of runs over ranks), and sets up ccache so rebuilds,
# including CI's fresh clones, reuse earlier compilations.

FASTSLAM_PACKAGES=(
  cmake ninja-build g++ pkg-config ccache git qemu-user
  libtbb-dev libeigen3-dev libjemalloc-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libcli11-dev nlohmann-json3-dev libnanoflann-dev
  python3 python3-numpy python3-matplotlib
  python3-dev pybind11-dev python3-pytest
  clang-14 libclang-rt-14-dev
  libopenmpi-dev openmpi-bin
)

fastslam_install_packages() {
  local missing=()
  local pkg
  for pkg in "${FASTSLAM_PACKAGES[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q 'install ok installed'; then
      missing+=("$pkg")
    fi
  done
  if [ ${#missing[@]} -eq 0 ]; then
    return 0
  fi
  echo "== Installing missing Debian packages: ${missing[*]}"
  local sudo=()
  if [ "$(id -u)" -ne 0 ]; then
    if ! command -v sudo >/dev/null 2>&1; then
      echo "error: packages missing (${missing[*]}) and neither root nor sudo available" >&2
      return 1
    fi
    sudo=(sudo)
  fi
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
    "${missing[@]}"
}

fastslam_setup_ccache() {
  # Compilations are keyed relative to the checkout, so a clone elsewhere hits the same cache.
  export CCACHE_BASEDIR="$FASTSLAM_ROOT"
  export CCACHE_NOHASHDIR=1
  export CCACHE_MAXSIZE="${CCACHE_MAXSIZE:-5G}"
}

# fastslam_build PRESET [TARGET...]: configure one CMake preset and build it (only the TARGETs
# when given).
fastslam_build() {
  local preset=$1
  shift
  local targets=()
  if [ $# -gt 0 ]; then
    targets=(--target "$@")
  fi
  echo "== Configuring and building preset '$preset'"
  cmake --preset "$preset" >"$FASTSLAM_ROOT/build/configure-$preset.log" 2>&1 || {
    cat "$FASTSLAM_ROOT/build/configure-$preset.log" >&2
    return 1
  }
  local log="$FASTSLAM_ROOT/build/build-$preset.log"
  if ! cmake --build --preset "$preset" "${targets[@]}" -- -j"$(nproc)" >"$log" 2>&1; then
    grep -v -E '^\[[0-9]+/[0-9]+\] (Building|Linking)' "$log" | tail -n 200 >&2
    return 1
  fi
  tail -n 1 "$log"
}
