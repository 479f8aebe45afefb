"""Rendering cost of the simulator per frame at 1280x960 on one core.

Prints, per frame: the full render (rays, textures, shading, shadow rays), the bare primary ray
cast of the same rays as a baseline (the part no shading work can remove), the finishing (sensor
noise, sRGB) and JPEG encoding.
Usage: .venv/bin/python bench/bench_render.py [--rocks 12] [--frames 10]
"""

from __future__ import annotations

import argparse
import os
import time

for var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(var, '1')

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import open3d as o3d  # noqa: E402

from stockpile_ros.camera import CameraModel  # noqa: E402
from stockpile_ros.tools.sim.camera_path import CartPath, PathConfig, auto_distance  # noqa: E402
from stockpile_ros.tools.sim.pile import PileConfig  # noqa: E402
from stockpile_ros.tools.sim.record import finish_image  # noqa: E402
from stockpile_ros.tools.sim.render import Renderer  # noqa: E402
from stockpile_ros.tools.sim.scene import SceneConfig, build_scene  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--rocks', type=int, default=12)
    parser.add_argument('--frames', type=int, default=10)
    parser.add_argument('--width', type=int, default=1280)
    parser.add_argument('--height', type=int, default=960)
    parser.add_argument('--threads', type=int, default=1, help='ray-casting threads (default 1)')
    args = parser.parse_args()
    cv2.setNumThreads(args.threads)

    t0 = time.perf_counter()
    scene = build_scene(0, SceneConfig(pile=PileConfig(rocks=args.rocks)))
    t_scene = time.perf_counter() - t0
    cam = CameraModel.from_fov(args.width, args.height, 70.0)
    renderer = Renderer(
        scene.rocks, cam, scene.rock_textures, scene.ground, scene.board, threads=args.threads
    )
    reach = max(float(np.linalg.norm(r.mesh.vertices[:, :2], axis=1).max()) for r in scene.rocks)
    path = CartPath(PathConfig(heights=(1.1,), distance=auto_distance(reach)), 10.0)
    poses = [path.camera_pose(float(t)) for t in np.linspace(0, 10, args.frames)]
    renderer.render(*poses[0])  # warm-up

    render_s, cast_s, finish_s, jpeg_s = [], [], [], []
    rng = np.random.default_rng(0)
    triangles = sum(len(r.mesh.faces) for r in scene.rocks)
    for position, rot in poses:
        t0 = time.perf_counter()
        res = renderer.render(position, rot)
        render_s.append(time.perf_counter() - t0)
        rays = renderer._rays  # the primary rays of that frame, as the renderer built them
        t0 = time.perf_counter()
        renderer.scene.cast_rays(o3d.core.Tensor.from_numpy(rays), nthreads=args.threads)
        cast_s.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        img = finish_image(res.linear, rng, 2.0)
        finish_s.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        cv2.imencode('.jpg', img[:, :, ::-1], [cv2.IMWRITE_JPEG_QUALITY, 90])
        jpeg_s.append(time.perf_counter() - t0)

    def med(xs: list[float]) -> float:
        return float(np.median(xs))

    print(f'scene: {args.rocks} rocks, {triangles} rock triangles, built in {t_scene:.2f} s')
    print(
        f'frames: {args.frames} at {args.width}x{args.height}, ray-casting threads {args.threads}'
    )
    print(f'render per frame (median):        {med(render_s):.3f} s  (min {min(render_s):.3f})')
    print(f'bare primary cast_rays baseline:  {med(cast_s):.3f} s  -> render / baseline = '
          f'{med(render_s) / med(cast_s):.2f}')  # fmt: skip
    print(f'noise + sRGB per frame:           {med(finish_s):.3f} s')
    print(f'JPEG encode per frame:            {med(jpeg_s):.3f} s')
    total = med(render_s) + med(finish_s) + med(jpeg_s)
    print(f'total per frame: {total:.3f} s (target: render under 0.5 s)')


if __name__ == '__main__':
    main()
