"""Benchmark of ``stockpile replay`` (issue 6): wall time of each part on one bag.

Replays BAG (or a freshly simulated one) into a temporary folder and prints the time spent reading
and selecting keyframes, in each reconstruction stage, in segmentation, and in total, with the
keyframe, registration and rock counts.

Usage:
    .venv/bin/python bench/bench_replay.py bags/demo
    .venv/bin/python bench/bench_replay.py --frames 16 --width 320 --height 240   # simulated
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from stockpile_ros.cli import main as stockpile
from stockpile_ros.replay import replay
from stockpile_ros.settings import build_settings, load_params_yaml


def _run(bag: Path, out: Path, params: Path | None) -> None:
    settings = build_settings(load_params_yaml(params) if params else {})
    start = time.perf_counter()
    summary = replay(bag, out, settings)
    total = time.perf_counter() - start
    stages = dict(summary.recon.seconds) if summary.recon else {}
    if summary.outcome is not None and 'segment' in summary.outcome.seconds:
        stages['segment'] = summary.outcome.seconds['segment']
    rest = total - sum(stages.values())
    print(f'bag {bag}: {summary.frames} frames, {summary.keyframes} keyframes')
    if summary.recon and summary.recon.sparse:
        print(f'registered {summary.recon.sparse.registered}')
    print(f'rocks {len(summary.report.rocks) if summary.report else "none"}')
    for name, seconds in stages.items():
        print(f'  {name:<10} {seconds:7.1f} s')
    print(f'  {"frames+io":<10} {rest:7.1f} s  (decode, keyframes, passthrough, messages)')
    print(f'  {"total":<10} {total:7.1f} s')


def main() -> None:
    """Parse arguments and run the benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', nargs='?', type=Path, help='bag to replay (default: simulate one)')
    parser.add_argument('--params', type=Path, help='parameters YAML')
    parser.add_argument('--frames', type=int, default=16)
    parser.add_argument('--width', type=int, default=320)
    parser.add_argument('--height', type=int, default=240)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        bag = args.bag
        if bag is None:
            bag = Path(tmp) / 'sim'
            stockpile(['simulate', '--out', str(bag), '--frames', str(args.frames),
                       '--width', str(args.width), '--height', str(args.height)])  # fmt: skip
        _run(bag, Path(tmp) / 'out', args.params)


if __name__ == '__main__':
    main()
