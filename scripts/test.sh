#!/usr/bin/env bash
# Set up, then run the whole check: lint, strict typing of the ROS-free core, tests.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/ruff check .
.venv/bin/ruff format --check .
.venv/bin/mypy
.venv/bin/pytest -q
