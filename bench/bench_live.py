"""The node set live on the demo bag, against `stockpile replay` of the same bag.

Runs the replay once, then the nodes live N times (all in one process: `rig`; or split: `rig
--role cart` and `rig --role base` with separate work folders), the bag published at real rate by
`stockpile-play` from another process and the reconstruction triggered through its service when
the bag ends. Prints, for each run, the keyframes, rocks and D50, the largest difference of any
rock's a, b, c, volume and centroid from the replay's, and the wall time from the first image the
keyframe node took to the last result.

    .venv/bin/python bench/bench_live.py bags/demo --runs 3 --split \\
        --set recon.target=charuco:5x4:0.08:0.06:DICT_4X4_50 --set gradation.spec_class=I
"""

from __future__ import annotations

import argparse
import signal
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import rclpy
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / 'tests'))

from live_graph import Recorder, play, rig, spin, trigger, wait

from stockpile_ros.bagio.reader import BagReader
from stockpile_ros.replay import replay
from stockpile_ros.ros import topics
from stockpile_ros.settings import build_settings


def _rocks(msg: Any) -> list[list[float]]:
    return [[r.a, r.b, r.c, r.volume, r.centroid.x, r.centroid.y, r.centroid.z] for r in msg.rocks]


def _largest_difference(live: list[list[float]], reference: list[list[float]]) -> float:
    """Largest difference of any rock's figure; inf when the rock counts differ."""
    if len(live) != len(reference):
        return float('inf')
    rows = zip(live, reference, strict=True)
    return max((abs(a - b) for x, y in rows for a, b in zip(x, y, strict=True)), default=0.0)


def _replayed(bag: Path, out: Path, params: dict[str, Any]) -> tuple[Any, Any, float]:
    start = time.perf_counter()
    summary = replay(bag, out, build_settings(params))
    seconds = time.perf_counter() - start
    if not summary.ok:
        sys.exit(f'replay failed: {summary.problems}')
    last: dict[str, Any] = {}
    with BagReader(out / 'replay.mcap') as reader:
        wanted = [topics.absolute(topics.ROCKS), topics.absolute(topics.GRADATION)]
        for name, _, _, msg in reader.messages(wanted):
            last[name] = msg
    return last[wanted[0]], last[wanted[1]], seconds


def _live(bag: Path, work: Path, params: dict[str, Any], split: bool) -> dict[str, Any]:
    roles = [('cart', work / 'cart'), ('base', work / 'base')] if split else [('all', work)]
    procs = [rig(role, folder, params) for role, folder in roles]
    rclpy.init()
    recorder = Recorder('stockpile_bench_recorder')
    executor, thread = spin(recorder)
    try:
        play(bag)
        if not trigger(recorder).success:
            sys.exit('the reconstruct service refused')
        wait(recorder, timeout_s=1200)
        first = recorder.times(topics.KEYFRAME_STATUS)[0]
        last = max(recorder.times(topics.GRADATION) + recorder.times(topics.STATUS))
        return {
            'keyframes': len(recorder.on(topics.KEYFRAMES)),
            'collected': recorder.on(topics.KEYFRAME_STATUS)[-1].message,
            'rocks': recorder.on(topics.ROCKS)[-1],
            'gradation': recorder.on(topics.GRADATION)[-1],
            'seconds': last - first,
        }
    finally:
        executor.shutdown()
        thread.join(5)
        recorder.destroy_node()
        rclpy.try_shutdown()
        for proc in procs:
            proc.send_signal(signal.SIGINT)
        codes = [proc.wait(timeout=60) for proc in procs]
        if codes != [0] * len(procs):
            print(f'  rig exit codes {codes}')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('bag', type=Path)
    parser.add_argument('--runs', type=int, default=3)
    parser.add_argument('--split', action='store_true', help='also one cart/base-station run')
    parser.add_argument('--set', action='append', default=[], metavar='NAME=VALUE')
    args = parser.parse_args()
    params = {k: yaml.safe_load(v) for k, _, v in (s.partition('=') for s in args.set)}
    with tempfile.TemporaryDirectory() as tmp:
        rocks, gradation, seconds = _replayed(args.bag, Path(tmp) / 'replay', params)
        print(f'replay: {len(rocks.rocks)} rocks, D50 {gradation.d50:.4f} m, {seconds:.1f} s')
        runs = [('all-in-one', False)] * args.runs + ([('cart/base', True)] if args.split else [])
        for i, (label, split) in enumerate(runs):
            got = _live(args.bag, Path(tmp) / f'live{i}', params, split)
            live, reference = _rocks(got['rocks']), _rocks(rocks)
            diff = _largest_difference(live, reference)
            print(f'{label} run {i + 1}: {got["keyframes"]} keyframes, {len(live)} rocks, '
                  f'D50 {got["gradation"].d50:.4f} m, max rock difference from replay '
                  f'{diff:.2e} m, first image to last result {got["seconds"]:.1f} s')  # fmt: skip
            print(f'  keyframe node: {got["collected"]}')


if __name__ == '__main__':
    main()
