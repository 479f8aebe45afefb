"""Cost growth with the number of keyframes: wall time and peak memory of every stage.

    .venv/bin/python bench/bench_cost.py --root DIR [--keyframes 20 40 80 160]
        [--width 1280 --height 960] [--set KEY=VALUE ...] [--stages STAGE ...]

For each count N an orbit of N frames round a pile of 14 rocks is simulated into DIR/orbitN
(once; reused after), and every frame is made a keyframe (``selector.min_spacing=1``, a viewing
angle of 0.1 deg, ``selector.max_keyframes=N``), so that the count is N whatever the selector's
defaults. The stages (keyframes, sfm, dense, mesh, segment) then run one after the other, each in
its own fresh process, so that its peak resident memory (``ru_maxrss``, which sees native
allocations that tracemalloc does not) is its own. Printed per stage: wall time, peak memory and
what it made. The machine's other load inflates the times; compare the counts within one run.
``--stages`` runs only the stages named, on what the earlier ones left in DIR/workN (to compare
one stage's cost before and after a change without redoing the others).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import resource
import shutil
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import yaml

from stockpile_ros.bagdrive import keyframes_from_bag
from stockpile_ros.recon.pipeline import reconstruct
from stockpile_ros.runner import run_segmentation
from stockpile_ros.settings import build_settings
from stockpile_ros.tools.sim.camera_path import PathConfig
from stockpile_ros.tools.sim.pile import PileConfig
from stockpile_ros.tools.sim.record import SimulationConfig, simulate
from stockpile_ros.tools.sim.scene import SceneConfig

STAGES = ('keyframes', 'sfm', 'dense', 'mesh', 'segment')
TARGET = 'charuco:5x4:0.08:0.06:DICT_4X4_50'


def _stage(stage: str, bag: Path, values: dict[str, Any], queue: Any) -> None:
    """Run one stage in this (child) process and send back seconds, peak KiB and a summary."""
    settings = build_settings(values)
    work = settings.work_dir
    start = time.perf_counter()
    try:
        if stage == 'keyframes':
            summary = f'{keyframes_from_bag(bag, settings).keyframes} keyframes'
        elif stage == 'segment':
            outcome = run_segmentation(settings, work / 'mesh')
            if not outcome.ok or outcome.analysis is None:
                raise RuntimeError(outcome.reason)
            summary = f'{len(outcome.analysis.report.rocks)} rocks'
        else:
            result: Any = reconstruct(None, work, settings.recon, stage)[stage]
            if stage == 'sfm':
                summary = f'{result.registered}/{result.total} registered'
            elif stage == 'dense':
                summary = f'{result.points} points'
            else:
                summary = f'{result.poisson["faces"]} faces'
    except Exception as exc:  # handed to the parent, which reports it
        queue.put(f'FAILED: {exc}')
        return
    seconds = time.perf_counter() - start
    queue.put((seconds, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, summary))


def run_count(
    root: Path, count: int, width: int, height: int, sets: dict[str, Any], stages: list[str]
) -> None:
    """Simulate (when missing) and reconstruct the N-keyframe orbit, printing each stage."""
    bag = root / f'orbit{count}'
    if not bag.exists():
        cfg = SimulationConfig(
            seed=40,
            scene=SceneConfig(pile=replace(PileConfig(), rocks=14)),
            path=PathConfig(kind='orbit'),
            width=width,
            height=height,
            fps=10.0,
            frames=count,
            jpeg_quality=80,
            odom_noise=0.005,
            threads=2,
        )
        simulate(cfg, bag)
    work = root / f'work{count}'
    if 'keyframes' in stages:
        shutil.rmtree(work, ignore_errors=True)
    values = {
        'work_dir': str(work),
        'recon.target': TARGET,
        'selector.min_spacing': 1,
        'selector.view_angle': 0.1,
        'selector.max_keyframes': count,
        **sets,
    }
    print(f'{count} keyframes, {width}x{height}:', flush=True)
    ctx = mp.get_context('spawn')
    total, peak = 0.0, 0
    for stage in stages:
        queue = ctx.Queue()
        proc = ctx.Process(target=_stage, args=(stage, bag, values, queue))
        proc.start()
        answer = queue.get()
        proc.join()
        if isinstance(answer, str):
            print(f'  {stage:10s} {answer}', flush=True)
            return
        seconds, peak_kib, summary = answer
        total += seconds
        peak = max(peak, peak_kib)
        print(
            f'  {stage:10s} {seconds:7.1f} s  peak {peak_kib / 2**20:5.2f} GiB  {summary}',
            flush=True,
        )
    print(f'  {"all":10s} {total:7.1f} s  peak {peak / 2**20:5.2f} GiB', flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--root', type=Path, required=True)
    parser.add_argument('--keyframes', type=int, nargs='+', default=[20, 40, 80, 160])
    parser.add_argument('--width', type=int, default=1280)
    parser.add_argument('--height', type=int, default=960)
    parser.add_argument('--set', action='append', default=[], metavar='KEY=VALUE')
    parser.add_argument('--stages', nargs='+', default=list(STAGES), choices=STAGES)
    args = parser.parse_args()
    sets = {}
    for item in args.set:
        key, _, value = item.partition('=')
        sets[key] = yaml.safe_load(value)
    for count in args.keyframes:
        run_count(args.root, count, args.width, args.height, sets, args.stages)


if __name__ == '__main__':
    main()
