#!/usr/bin/env bash
# One-time set-up on Debian/Ubuntu with Python 3.10-3.12: system library, virtual environment, package.
# Idempotent: re-running it only installs what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

# open3d needs libusb at import time; everything else comes from PyPI.
if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
  sudo_cmd=''
  [ "$(id -u)" -eq 0 ] || sudo_cmd='sudo'
  $sudo_cmd apt-get update -qq
  $sudo_cmd apt-get install -y -qq libusb-1.0-0 python3-venv >/dev/null
fi

python=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$python" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e '.[test]'
