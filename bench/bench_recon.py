"""Reconstruction benchmark (prints figures; run on the 2-core machine, nothing else running).

    .venv/bin/python bench/bench_recon.py BAG --work DIR [--target SPEC] [--growth 20 40 80]
        [--truth BAG_truth]

1. Keyframe selection cost per 1280x720 frame (median and 95th percentile over the bag's frames
   resized to 1280x720, one thread).
2. First frame to mesh: every stage in its own process (so that its peak resident memory is its
   own), 2 threads, time and peak RSS per stage.
3. With --growth: SfM, dense and mesh time for the given keyframe counts (every n-th frame).
4. With --truth: the figures of bench/eval_recon.py for the full run.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import resource
import shutil
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from stockpile_ros.recon.keyframes import KeyframeSelector, KeyframeStore
from stockpile_ros.recon.options import ReconOptions
from stockpile_ros.recon.pipeline import reconstruct
from stockpile_ros.recon.scale import TargetSpec
from stockpile_ros.recon.sources import iter_frames


def selection_cost(bag: Path) -> tuple[float, float, int]:
    cv2.setNumThreads(1)
    frames = [cv2.resize(f.image, (1280, 720)) for f in iter_frames(bag)]
    selector = KeyframeSelector()
    times = []
    for img in frames:
        start = time.perf_counter()
        selector.push(img)
        times.append(time.perf_counter() - start)
    cv2.setNumThreads(-1)
    return float(np.median(times)) * 1e3, float(np.percentile(times, 95)) * 1e3, len(frames)


def _stage(args: tuple[Path | None, Path, ReconOptions, str], queue: Any) -> None:
    source, work, options, stage = args
    start = time.perf_counter()
    try:
        result = reconstruct(source, work, options, stage)[stage]
    except Exception as exc:  # handed to the parent, which reports it
        queue.put(RuntimeError(f'{stage}: {exc}'))
        return
    seconds = time.perf_counter() - start
    queue.put((seconds, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, result))


def run_stages(source: Path, work: Path, options: ReconOptions) -> float:
    shutil.rmtree(work, ignore_errors=True)
    total = 0.0
    ctx = mp.get_context('spawn')
    for stage in ('keyframes', 'sfm', 'dense', 'mesh'):
        # One process per stage: its peak resident memory is the stage's own.
        queue = ctx.Queue()
        proc = ctx.Process(target=_stage, args=((source, work, options, stage), queue))
        proc.start()
        answer = queue.get()
        proc.join()
        if isinstance(answer, Exception):
            raise answer
        seconds, peak_kib, result = answer
        total += seconds
        extra = ''
        if stage == 'keyframes':
            extra = f'{result["keyframes"]} keyframes of {result["frames"]} frames'
        elif stage == 'sfm':
            extra = (
                f'{result["registered"]}/{result["total"]} registered, '
                f'{result["points"]} points, {result["mean_reprojection_error_px"]:.2f} px'
            )
        elif stage == 'dense':
            extra = f'{result["points"]} points'
        else:
            extra = f'{result["poisson"]["faces"]} faces, scale {result["scale"]["method"]}'
        print(f'  {stage:10s} {seconds:7.1f} s  peak RSS {peak_kib / 1024:7.0f} MiB  {extra}')
    print(f'  {"total":10s} {total:7.1f} s (first frame to mesh, process start-up excluded)')
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('bag', type=Path)
    parser.add_argument('--work', type=Path, required=True)
    parser.add_argument('--target')
    parser.add_argument('--growth', type=int, nargs='*', default=[])
    parser.add_argument('--truth', type=Path)
    parser.add_argument('--skip-full', action='store_true')
    args = parser.parse_args()
    options = ReconOptions(target=TargetSpec.parse(args.target) if args.target else None)

    median_ms, p95_ms, frames = selection_cost(args.bag)
    print(
        f'keyframe selection per 1280x720 frame: median {median_ms:.2f} ms, '
        f'95th percentile {p95_ms:.2f} ms ({frames} frames, 1 thread)'
    )

    if not args.skip_full:
        print(f'first frame to mesh, {args.bag}:')
        run_stages(args.bag, args.work / 'full', options)
        if args.truth is not None:
            sys.path.insert(0, str(Path(__file__).parent))
            from eval_recon import evaluate

            for key, value in evaluate(args.work / 'full', args.truth).items():
                print(
                    f'  {key:32s} {value:.5g}'
                    if isinstance(value, float)
                    else f'  {key:32s} {value}'
                )

    for count in args.growth:
        spacing = max(1, frames // count)
        selector = replace(
            options.selector,
            min_parallax=1.0,
            min_tracked=0.0,
            min_spacing=1,
            max_spacing=spacing,
            max_keyframes=count,
        )
        print(f'{count} keyframes (every {spacing}th frame):')
        work = args.work / f'growth{count}'
        run_stages(args.bag, work, replace(options, selector=selector))
        print(f'  kept {len(KeyframeStore(work / "keyframes").records)} keyframes')


if __name__ == '__main__':
    main()
