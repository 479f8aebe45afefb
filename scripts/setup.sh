#!/usr/bin/env bash
# One-time set-up on Debian/Ubuntu with Python 3.10-3.12: system packages, virtual environment,
# the package itself, then ROS 2 Jazzy and our interface packages (scripts/setup_ros.sh).
# Idempotent: re-running it only installs what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
python=${PYTHON:-python3}

# open3d needs libusb at import time; venv needs ensurepip (python3-venv on Debian/Ubuntu).
missing=()
ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0' || missing+=(libusb-1.0-0)
[ -x .venv/bin/python ] || "$python" -c 'import ensurepip' 2>/dev/null || missing+=(python3-venv)
if [ ${#missing[@]} -gt 0 ]; then
  sudo_cmd=''
  [ "$(id -u)" -eq 0 ] || sudo_cmd='sudo'
  $sudo_cmd apt-get update -qq
  $sudo_cmd apt-get install -y -qq "${missing[@]}" >/dev/null
fi

if [ ! -x .venv/bin/python ]; then
  "$python" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e '.[test]'
# After the project: the interface packages compile against the numpy installed above.
bash scripts/setup_ros.sh
