#!/usr/bin/env bash
# Set up, then run the main job on the demo bag: keyframes -> SfM -> dense -> mesh -> rocks -> report.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
rm -rf out/demo
.venv/bin/stockpile replay bags/demo --out out/demo
