"""The keyframe selector's image-only viewing angle against the true one, on rendered views.

    .venv/bin/python bench/bench_view_angle.py [--corners N ...]

Three scenes of the tests (``tests/recon_synth.py``: ellipsoid rocks on a textured 4 m ground),
each seen from an orbit that keeps the origin in view (3-degree steps to 30 degrees, steeply or
gently down, near or far) and from a straight sideways pass looking at the pile (6 cm steps) at
640x480. Pairs of views (from two starting views of each sequence, true angle of 2 degrees or
more) go through :class:`~stockpile_ros.recon.keyframes.KeyframeSelector` as a keyframe and a
frame, without poses, with CameraInfo and without it (the assumed 75-degree field of view for
the true 70). Printed per path and camera: the median, 10th and 90th percentile of the estimate
over the true angle (the median over the ray-cast scene points of the keyframe's pixel grid, as
the tests take it), the share within 40 %, and the selector's time per frame.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from stockpile_ros.camera import CameraModel
from stockpile_ros.recon.keyframes import KeyframeSelector, SelectorOptions

sys.path.insert(0, str(Path(__file__).parents[1] / 'tests'))
from recon_synth import look_at, render, scene_mesh, seen_points, viewing_angle

SIZE = (640, 480)
# (seed, orbit radius [m], camera height [m]) of the three scenes.
SCENES = ((0, 1.6, 2.0), (1, 2.2, 1.2), (2, 1.2, 1.6))


def sequences() -> list[tuple[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]]]:
    """Rendered (image, centre, scene points seen) sequences: one orbit and one line a scene."""
    cam = CameraModel.from_fov(SIZE[0], SIZE[1], 70.0)
    out = []
    for seed, radius, height in SCENES:
        mesh = scene_mesh(seed=seed)
        orbit = [
            (np.array([radius * np.cos(a), radius * np.sin(a), height]), np.zeros(3))
            for a in np.radians(np.arange(0.0, 31.0, 3.0))
        ]
        line = [
            (np.array([x, -radius, height]), np.array([x, 0.0, 0.0]))
            for x in np.arange(-0.3, 0.31, 0.06)
        ]
        for name, poses in (('orbit', orbit), ('line', line)):
            seq = []
            for centre, target in poses:
                rot, trans = look_at(centre, target)
                image = render(mesh, cam.k, SIZE, rot, trans)
                seq.append((image, centre, seen_points(mesh, cam.k, SIZE, rot, centre)))
            out.append((name, seq))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--corners', type=int, nargs='*', default=[SelectorOptions().max_corners])
    args = parser.parse_args()
    cam = CameraModel.from_fov(SIZE[0], SIZE[1], 70.0)
    seqs = sequences()
    for corners in args.corners:
        options = SelectorOptions(
            blur_ratio=0.0, view_angle=90.0, max_view_angle=90.0, min_parallax=1.0,
            min_tracked=0.0, max_spacing=0, max_corners=corners,
        )  # fmt: skip
        ratios: dict[tuple[str, bool], list[float]] = {}
        spent, frames = 0.0, 0
        for name, seq in seqs:
            for camera in (cam, None):
                for first in (0, 3):
                    image0, centre0, points0 = seq[first]
                    for image, centre, _ in seq[first + 1 :]:
                        truth = viewing_angle(points0, centre0, centre)
                        if truth < 2.0:
                            continue
                        sel = KeyframeSelector(options)
                        sel.push(image0, camera)
                        start = time.perf_counter()
                        decision = sel.push(image, camera)
                        spent += time.perf_counter() - start
                        frames += 1
                        ratios.setdefault((name, camera is not None), []).append(
                            decision.view_angle / truth
                        )
        print(f'{corners} corners, {1000 * spent / frames:.0f} ms a frame')
        for (name, with_camera), values in sorted(ratios.items()):
            r = np.asarray(values)
            print(
                f'  {name:5s} {"CameraInfo" if with_camera else "no camera ":10s} {len(r):3d} pairs'
                f'  estimate/true median {np.median(r):.2f}'
                f'  p10 {np.percentile(r, 10):.2f}  p90 {np.percentile(r, 90):.2f}'
                f'  within 40 % {np.mean(np.abs(r - 1) < 0.4):.2f}'
            )


if __name__ == '__main__':
    main()
