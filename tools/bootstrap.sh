#!/usr/bin/env bash
# Create or refresh .venv/: ROS 2 Kilted wheels, Python dependencies, the ssa_fusion_msgs
# interface package (built with CMake into the venv prefix) and ssa_fusion itself (editable,
# with its node executables in lib/ssa_fusion/ and its data_files in share/, as colcon would).
#
# Idempotent: every step records a fingerprint of its inputs in .venv/.bootstrap/ and is
# skipped when nothing changed. Fails loudly naming the step that failed.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
STAMPS="$VENV/.bootstrap"
PY_WANT="3.11"

step() { CURRENT_STEP="$1"; echo "bootstrap: $1" >&2; }
# long_step LOG LABEL COMMAND...: a line at least every BOOTSTRAP_TICK_S s while it runs
# shellcheck source=tools/long_step.sh
source "$ROOT/tools/long_step.sh"
trap 'echo "bootstrap: FAILED at step: ${CURRENT_STEP:-start} (see output above)" >&2' ERR

fingerprint() { cat "$@" | sha256sum | cut -c1-16; }
is_fresh() { [[ -f "$STAMPS/$1" && "$(cat "$STAMPS/$1")" == "$2" ]]; }
mark() { mkdir -p "$STAMPS"; echo "$2" > "$STAMPS/$1"; }

find_python() {
  for cand in "${PYTHON:-}" python3.11 python3; do
    [[ -n "$cand" ]] || continue
    if command -v "$cand" >/dev/null 2>&1 &&
       [[ "$("$cand" -c 'import sys; print("%d.%d" % sys.version_info[:2])')" == "$PY_WANT" ]]; then
      command -v "$cand"; return 0
    fi
  done
  echo "bootstrap: need Python $PY_WANT (the ROS 2 Kilted wheels are cp311); set PYTHON=" >&2
  return 1
}

# 1. virtual environment ----------------------------------------------------------------
if [[ ! -x "$VENV/bin/python" ]]; then
  step "create .venv with Python $PY_WANT"
  PY_BASE="$(find_python)"
  long_step "$VENV/.bootstrap-logs/venv.log" "venv" "$PY_BASE" -m venv "$VENV"
fi
PY="$VENV/bin/python"
export PIP_DISABLE_PIP_VERSION_CHECK=1

# 2. pinned wheels ------------------------------------------------------------------------
REQ_FP=$(fingerprint "$ROOT/requirements/ros.txt" "$ROOT/requirements/python.txt")
if ! is_fresh requirements "$REQ_FP"; then
  step "pip install requirements/ros.txt requirements/python.txt (a few minutes the first time)"
  long_step "$VENV/.bootstrap-logs/pip.log" "pip" \
    "$PY" -m pip install --progress-bar off -r "$ROOT/requirements/ros.txt" \
    -r "$ROOT/requirements/python.txt"
  # The wheels' CMake exports name the build host's Python and numpy include dirs.
  step "point the ROS wheels' CMake exports at this interpreter"
  PYINC=$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
  NPINC=$("$PY" -c 'import numpy; print(numpy.get_include())')
  # grep exits 1 when there is nothing left to patch (a venv whose wheels were patched before).
  { grep -rl --include='*__rosidl_generator_pyExport.cmake' '/opt/python/cp311-cp311' "$VENV/share" ||
    [[ $? == 1 ]]; } |
    xargs -r sed -i \
      -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$NPINC#g" \
      -e "s#/opt/python/cp311-cp311/include/python3.11#$PYINC#g"
  rm -f "$STAMPS/msgs"
  mark requirements "$REQ_FP"
fi

# 3. ssa_fusion_msgs ---------------------------------------------------------------------
MSG_FP=$(fingerprint "$ROOT"/msg_defs/package.xml "$ROOT"/msg_defs/CMakeLists.txt "$ROOT"/msg_defs/msg/*.msg)
if ! is_fresh msgs "$MSG_FP"; then
  step "build msg_defs (ssa_fusion_msgs) with CMake into the venv prefix"
  BUILD="$VENV/.build/ssa_fusion_msgs"
  rm -rf "$BUILD"; mkdir -p "$BUILD"
  export AMENT_PREFIX_PATH="$VENV"
  long_step "$BUILD.configure.log" "cmake configure" \
    cmake -S "$ROOT/msg_defs" -B "$BUILD" -DCMAKE_BUILD_TYPE=Release \
    -DCMAKE_PREFIX_PATH="$VENV" -DCMAKE_INSTALL_PREFIX="$VENV" \
    -DPython3_EXECUTABLE="$PY" -DBUILD_TESTING=OFF
  long_step "$BUILD.build.log" "cmake build" cmake --build "$BUILD" -j "$(nproc)"
  long_step "$BUILD.install.log" "cmake install" cmake --install "$BUILD"
  step "check: import ssa_fusion_msgs in a clean environment"
  env -i "$PY" -c 'from ssa_fusion_msgs.msg import Measurement, StateEstimate'
  mark msgs "$MSG_FP"
fi

# 4. ssa_fusion itself (editable) + executables for `ros2 run` ------------------------------
PKG_FP=$(fingerprint "$ROOT/setup.py" "$ROOT/setup.cfg" "$ROOT/package.xml")
if ! is_fresh package "$PKG_FP" || [[ ! -d "$VENV/lib/ssa_fusion" ]]; then
  step "pip install -e . (ssa_fusion)"
  long_step "$VENV/.bootstrap-logs/pip-e.log" "pip install -e ." \
    "$PY" -m pip install --progress-bar off --no-deps --no-build-isolation -e "$ROOT"
  step "place node executables in .venv/lib/ssa_fusion for ros2 run"
  mkdir -p "$VENV/lib/ssa_fusion"
  "$PY" - "$VENV" <<'PYEOF'
import sys
from importlib.metadata import entry_points
from pathlib import Path

venv = Path(sys.argv[1])
libdir = venv / "lib" / "ssa_fusion"
for ep in entry_points(group="console_scripts"):
    if ep.value.startswith("ssa_fusion.nodes."):
        src = venv / "bin" / ep.name
        dst = libdir / ep.name
        dst.unlink(missing_ok=True)
        dst.symlink_to(src)
PYEOF
  mark package "$PKG_FP"
fi

# 5. setup.py's data_files into the venv prefix, as `colcon build` installs them ----------
# (`pip install -e .` installs none): the ament index marker and share/ssa_fusion/
# {package.xml,launch/,config/}, so that `ros2 run`/`ros2 launch` find the package with the
# venv on AMENT_PREFIX_PATH. The file list is setup.py's own (read with setup() stubbed).
SHARE_FILES=$(cd "$ROOT" && "$PY" - <<'PYEOF'
import runpy
from unittest import mock

with mock.patch("setuptools.setup") as setup:
    runpy.run_path("setup.py")
for dest, files in setup.call_args.kwargs["data_files"]:
    for f in files:
        print(f"{dest}\t{f}")
PYEOF
)
SHARE_FP=$( { echo "$SHARE_FILES"; cd "$ROOT" && cut -f2 <<<"$SHARE_FILES" | xargs -r cat; } |
  sha256sum | cut -c1-16)
if ! is_fresh share "$SHARE_FP" || [[ ! -f "$VENV/share/ssa_fusion/package.xml" ]]; then
  step "install setup.py's data_files (ament index marker, share/ssa_fusion) into .venv"
  rm -rf "$VENV/share/ssa_fusion"  # ours alone: no stale launch or config file stays
  while IFS=$'\t' read -r dest file; do
    mkdir -p "$VENV/$dest"
    cp "$ROOT/$file" "$VENV/$dest/"
  done <<<"$SHARE_FILES"
  mark share "$SHARE_FP"
fi
echo "bootstrap: .venv ready" >&2
