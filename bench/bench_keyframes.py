"""Keyframes kept and registered on simulated camera paths, with the default parameters.

    .venv/bin/python bench/bench_keyframes.py --work DIR [--only NAME ...] [--no-sfm]

For each path (arc, orbit, straight line; near and far; slow and fast; one and two heights) a
small pile is rendered at 640x480 into a bag, keyframes are selected from it as the nodes select
them (:func:`stockpile_ros.bagdrive.keyframes_from_bag`), and Structure-from-Motion runs on the
kept keyframes. Printed per path: frames, keyframes kept, registered (largest model), models,
the registration gate's verdict, and, scored against the simulator's true camera poses, the
largest and median viewing-angle change between consecutive keyframes (at the scene point on
the earlier keyframe's optical axis at the pile's mid height) beside the selector's own estimate.
"""

from __future__ import annotations

import argparse
import itertools
import json
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from stockpile_ros.artefacts import WorkFolder
from stockpile_ros.bagdrive import keyframes_from_bag
from stockpile_ros.errors import CaptureError
from stockpile_ros.recon.keyframes import KeyframeStore
from stockpile_ros.recon.pipeline import reconstruct
from stockpile_ros.settings import build_settings
from stockpile_ros.tools.sim.camera_path import PathConfig
from stockpile_ros.tools.sim.pile import PileConfig
from stockpile_ros.tools.sim.record import SimulationConfig, simulate, truth_folder
from stockpile_ros.tools.sim.scene import SceneConfig

AIM_HEIGHT = 0.1


@dataclass(frozen=True)
class Case:
    """One simulated capture."""

    name: str
    path: PathConfig
    frames: int


CASES = (
    Case('arc-near-slow', PathConfig(kind='arc'), 60),
    Case('arc-far-fast', PathConfig(kind='arc', distance=3.0), 20),
    Case('orbit-near-slow', PathConfig(kind='orbit'), 90),
    Case('orbit-near-fast', PathConfig(kind='orbit'), 36),
    Case('orbit-far-2h', PathConfig(kind='orbit', distance=3.0, heights=(1.0, 1.8)), 80),
    Case('line-near-slow', PathConfig(kind='straight'), 60),
    Case('line-far-fast', PathConfig(kind='straight', distance=3.0), 20),
    Case('arc-near-2h', PathConfig(kind='arc', heights=(0.8, 1.4)), 60),
)


def true_angles(truth: dict[str, object], stamps: list[int]) -> list[float]:
    """True viewing-angle change [deg] between consecutive keyframes (scoring only)."""
    cams = {int(c['stamp_ns']): c for c in truth['cameras']}  # type: ignore[attr-defined]
    out = []
    for a, b in itertools.pairwise(stamps):
        ca, cb = np.asarray(cams[a]['position']), np.asarray(cams[b]['position'])
        axis = Rotation.from_quat(cams[a]['orientation_xyzw']).as_matrix()[:, 2]
        point = ca + axis * (AIM_HEIGHT - ca[2]) / axis[2]
        ra, rb = point - ca, point - cb
        cos = ra @ rb / np.linalg.norm(ra) / np.linalg.norm(rb)
        out.append(float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))))
    return out


def run_case(case: Case, root: Path, sfm: bool) -> str:
    """Simulate, select and reconstruct one case; return its line."""
    bag = root / case.name / 'bag'
    if not bag.exists():
        cfg = SimulationConfig(
            seed=3,
            scene=SceneConfig(pile=PileConfig(rocks=12, subdivisions=3), ground_px=1024),
            path=case.path,
            width=640,
            height=480,
            fps=10.0,
            frames=case.frames,
            threads=2,
        )
        simulate(cfg, bag)
    work = root / case.name / 'work'
    shutil.rmtree(work, ignore_errors=True)
    settings = build_settings({'work_dir': str(work)})
    start = time.perf_counter()
    kept = keyframes_from_bag(bag, settings)
    records = KeyframeStore(WorkFolder(work).keyframes).records
    truth = json.loads((truth_folder(bag) / 'truth.json').read_text())
    angles = true_angles(truth, [r.stamp_ns for r in records])
    line = (
        f'{case.name:16s} {case.frames:4d} frames  {kept.keyframes:3d} kept  '
        f'true angle max {max(angles, default=0):5.1f} median {np.median(angles):5.1f} deg'
    )
    if sfm:
        verdict = 'pass'
        try:
            reconstruct(None, work, settings.recon, 'sfm')
        except CaptureError as exc:
            verdict = f'FAIL: {exc.reason}'
        report = json.loads((WorkFolder(work).sparse / 'sparse.json').read_text())
        line += (
            f'  {report["registered"]:3d} registered ({100 * report["registered_fraction"]:.0f} %)'
            f' in {report["models"]} model(s), span {report["gate"]["span_deg"]:.0f} deg; '
            f'gate {verdict}'
        )
    return line + f'  [{time.perf_counter() - start:.0f} s]'


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--work', type=Path, required=True)
    parser.add_argument('--only', nargs='*', default=[])
    parser.add_argument('--no-sfm', action='store_true')
    args = parser.parse_args()
    for case in CASES:
        if args.only and case.name not in args.only:
            continue
        print(run_case(case, args.work, not args.no_sfm), flush=True)


if __name__ == '__main__':
    main()
