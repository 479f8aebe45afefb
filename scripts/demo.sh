#!/usr/bin/env bash
# Set up, then run the main job on the demo bag: keyframes -> SfM -> dense -> mesh -> rocks -> report.
# The demo pile has a 5x4 ChArUco board (8 cm squares, 6 cm markers) beside it and is checked
# against riprap class I (nominal D50 6 in, config/riprap_classes.yaml).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
rm -rf out/demo
.venv/bin/stockpile replay bags/demo --out out/demo \
  --set recon.target=charuco:5x4:0.08:0.06:DICT_4X4_50 --set gradation.spec_class=I
