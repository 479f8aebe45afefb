"""How far the reconstructed rock surface lies from the true one, and where the error comes from.

    .venv/bin/python bench/bench_surface.py --root DIR [--paths arc orbit line]
        [--width 800 --height 600] [--variant NAME:KEY=VALUE,KEY=VALUE ...] [--true-poses]
        [--tag TAG]

For each camera path (and a harder pile of smaller rocks) a pile is simulated into DIR/PATH (once;
reused after), its keyframes are selected and Structure-from-Motion runs once (DIR/PATH_work).
Then, for the defaults and for each ``--variant`` (parameters by dotted name, as ``--set`` takes
them), the dense and mesh stages run on a copy of that work folder and are scored as
bench/eval_recon.py scores them: the area-weighted median distance from the mesh's rock surface
(the mesh parts whose nearest true surface is a rock) to the true surface, over the median rock
b, with the two stages' time beside the defaults' in the same run.

With ``--true-poses`` the error is also taken apart with the true camera poses (so SfM plays no
part): the signed depth error of single stereo pairs along their rays (a bias shows as a median
away from 0), the distance from the fused dense points on rocks to the true surface, and the same
for a Poisson mesh of those points (cropped as the mesh stage crops).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import open3d as o3d
from scipy.spatial.transform import Rotation

from stockpile_ros.bagdrive import keyframes_from_bag
from stockpile_ros.camera import CameraModel
from stockpile_ros.meshio import LabelledMesh, read_labelled_mesh
from stockpile_ros.recon.dense import (
    DenseOptions,
    _depth_stats,
    _pair_depth,
    _pick_partners,
    dense_cloud,
)
from stockpile_ros.recon.ground import pile_mask
from stockpile_ros.recon.keyframes import KeyframeStore
from stockpile_ros.recon.pipeline import reconstruct
from stockpile_ros.recon.sfm import SparseModel, View, load_sparse
from stockpile_ros.recon.surface import PoissonOptions, poisson_surface
from stockpile_ros.settings import Settings, build_settings
from stockpile_ros.tools.sim.camera_path import PathConfig
from stockpile_ros.tools.sim.pile import PileConfig, parse_gradation
from stockpile_ros.tools.sim.record import SimulationConfig, simulate, truth_folder
from stockpile_ros.tools.sim.scene import SceneConfig

sys.path.insert(0, str(Path(__file__).parent))
from eval_recon import align_keyframes, evaluate, rock_surface_distance

F64 = npt.NDArray[np.float64]
# Name: path kind, seed, rocks, gradation of b [m]. "small": rocks of half the size, three times
# as many, a harder case than the others (the same pixel error is twice the share of b).
CASES = {
    'arc': ('arc', 31, 14, '0.12:0.3'),
    'orbit': ('orbit', 32, 14, '0.12:0.3'),
    'line': ('straight', 33, 14, '0.12:0.3'),
    'small': ('arc', 34, 40, '0.06:0.15'),
}
TARGET = 'charuco:5x4:0.08:0.06:DICT_4X4_50'


def prepare(root: Path, name: str, width: int, height: int) -> tuple[Path, Path]:
    """Simulate the path's bag (when missing) and run keyframes and SfM once; their folders."""
    bag, work = root / name, root / f'{name}_work'
    if not bag.exists():
        kind, seed, rocks, gradation = CASES[name]
        pile = replace(PileConfig(), rocks=rocks, gradation=parse_gradation(gradation))
        cfg = SimulationConfig(
            seed=seed,
            scene=SceneConfig(pile=pile),
            path=PathConfig(kind=kind),
            width=width,
            height=height,
            fps=10.0,
            frames=101,
            jpeg_quality=80,
            odom_noise=0.005,
            threads=2,
        )
        simulate(cfg, bag)
    if not (work / 'sparse' / 'sparse.json').exists():
        shutil.rmtree(work, ignore_errors=True)
        settings = build_settings({'work_dir': str(work), 'recon.target': TARGET})
        keyframes_from_bag(bag, settings)
        reconstruct(None, work, settings.recon, 'sfm')
    return bag, work


def run_variant(work: Path, out: Path, sets: dict[str, Any]) -> tuple[Settings, float]:
    """Dense and mesh stages on a copy of ``work`` with ``sets``; the settings and seconds."""
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    for part in ('keyframes', 'sparse'):
        shutil.copytree(work / part, out / part)
    settings = build_settings({'work_dir': str(out), 'recon.target': TARGET, **sets})
    start = time.perf_counter()
    reconstruct(None, out, settings.recon, 'dense')
    reconstruct(None, out, settings.recon, 'mesh')
    return settings, time.perf_counter() - start


def true_pose_model(work: Path, truth: dict[str, Any]) -> SparseModel:
    """The sparse model with every view at its true pose, in the truth frame (metres).

    The sparse points (which only set the disparity search ranges) are carried over by the
    similarity that aligns the model's cameras to the true ones.
    """
    model = load_sparse(work / 'sparse')
    stamps = {r.file: r.stamp_ns for r in KeyframeStore(work / 'keyframes').records}
    keyframes = [
        {
            'stamp_ns': stamps[name],
            'position': view.center.tolist(),
            'orientation_xyzw': Rotation.from_matrix(view.rotation.T).as_quat().tolist(),
        }
        for name, view in model.views.items()
    ]
    sim, _ = align_keyframes(keyframes, truth)
    cameras = {int(c['stamp_ns']): c for c in truth['cameras']}
    true_stamps = np.array(sorted(cameras))
    cam = truth['camera']
    camera = CameraModel(
        int(cam['width']), int(cam['height']), np.reshape(cam['k'], (3, 3)), np.asarray(cam['d'])
    )
    views = {}
    for name, view in model.views.items():
        nearest = cameras[int(true_stamps[np.argmin(np.abs(true_stamps - stamps[name]))])]
        rot = Rotation.from_quat(nearest['orientation_xyzw']).as_matrix().T
        views[name] = View(
            name, camera, rot, -rot @ np.asarray(nearest['position']), view.point_ids
        )
    return SparseModel(views, model.point_ids, sim.apply(model.points), model.colors)


def _raycaster(scene: LabelledMesh) -> o3d.t.geometry.RaycastingScene:
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(
        o3d.core.Tensor.from_numpy(scene.vertices.astype(np.float32)),
        o3d.core.Tensor.from_numpy(scene.faces.astype(np.uint32)),
    )
    return rc


def pair_bias(
    work: Path, model: SparseModel, scene: LabelledMesh, options: DenseOptions, every: int = 3
) -> dict[str, float]:
    """Signed relative depth error along the rays of single stereo pairs, on rocks and ground."""
    order = [r.file for r in KeyframeStore(work / 'keyframes').records if r.file in model.views]
    views = [model.views[n] for n in order]
    stats = [_depth_stats(v, model) for v in views]
    rc = _raycaster(scene)
    rel: dict[str, list[F64]] = {'rock': [], 'ground': []}
    for i in range(0, len(views), every):
        partners = _pick_partners(i, views, stats, options)
        dv = _pair_depth(work / 'keyframes', views[i], views[partners[0]], model, options, {})
        if dv is None:
            continue
        rays = dv.points - views[i].center
        dist = np.linalg.norm(rays, axis=1)
        query = np.hstack([np.broadcast_to(views[i].center, rays.shape), rays / dist[:, None]])
        hit = rc.cast_rays(o3d.core.Tensor(query.astype(np.float32)))
        t = hit['t_hit'].numpy().astype(np.float64)
        ok = np.isfinite(t)
        labels = scene.labels[np.where(ok, hit['primitive_ids'].numpy(), 0).astype(np.int64)]
        err = dist / np.where(ok, t, 1.0) - 1.0
        rel['rock'].append(err[ok & (labels > 0)])
        rel['ground'].append(err[ok & (labels == 0)])
    out = {}
    for key, parts in rel.items():
        values = np.concatenate(parts)
        out[f'pair_{key}_median_rel_depth'] = float(np.median(values))
        out[f'pair_{key}_mad_rel_depth'] = float(np.median(np.abs(values - np.median(values))))
    return out


def true_pose_figures(
    work: Path, truth_dir: Path, dense: DenseOptions, poisson: PoissonOptions, crop: float
) -> dict[str, float]:
    """Stereo, fusion and Poisson errors with the true camera poses."""
    truth = json.loads((truth_dir / 'truth.json').read_text())
    scene = read_labelled_mesh(truth_dir / 'scene.ply')
    b = float(np.median([r['b'] for r in truth['rocks']]))
    model = true_pose_model(work, truth)
    out = pair_bias(work, model, scene, dense)
    order = [r.file for r in KeyframeStore(work / 'keyframes').records]
    cloud, _ = dense_cloud(work / 'keyframes', model, order, dense)
    points = np.asarray(cloud.points)
    hit = _raycaster(scene).compute_closest_points(o3d.core.Tensor(points.astype(np.float32)))
    dist = np.linalg.norm(hit['points'].numpy() - points, axis=1)
    on_rock = scene.labels[hit['primitive_ids'].numpy().astype(np.int64)] > 0
    out['cloud_rock_median_rel_b'] = float(np.median(dist[on_rock]) / b)
    # The mesh stage's crop: around the pile, never past the farthest camera.
    horizontal = np.linalg.norm(points[:, :2], axis=1)
    centres = np.array([v.center for v in model.views.values()])
    radius = float(np.max(np.linalg.norm(centres[:, :2], axis=1)))
    above = pile_mask(points[:, 2])
    radius = min(radius, crop * float(np.percentile(horizontal[above], 95)))
    keep = horizontal <= radius
    mesh, _ = poisson_surface(points[keep], np.asarray(cloud.normals)[keep], None, poisson)
    figures = rock_surface_distance(
        np.asarray(mesh.vertices), np.asarray(mesh.triangles, dtype=np.int64), scene, b
    )
    out['mesh_rock_median_rel_b'] = figures['rock_median_rel_b']
    return out


def parse_variant(text: str) -> tuple[str, dict[str, Any]]:
    """``NAME:KEY=VALUE,KEY=VALUE`` -> the name and the values (YAML scalars)."""
    import yaml

    name, _, rest = text.partition(':')
    sets = {}
    for item in filter(None, rest.split(',')):
        key, _, value = item.partition('=')
        sets[key] = yaml.safe_load(value)
    return name, sets


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--root', type=Path, required=True)
    parser.add_argument('--paths', nargs='+', default=list(CASES), choices=list(CASES))
    parser.add_argument('--width', type=int, default=800)
    parser.add_argument('--height', type=int, default=600)
    parser.add_argument('--variant', nargs='*', default=[])
    parser.add_argument('--true-poses', action='store_true')
    parser.add_argument('--tag', default='', help='prefix of the variant folders (parallel runs)')
    args = parser.parse_args()
    variants = [('defaults', {})] + [parse_variant(v) for v in args.variant]
    print(f'images {args.width}x{args.height}')
    for name in args.paths:
        bag, work = prepare(args.root, name, args.width, args.height)
        sparse = json.loads((work / 'sparse' / 'sparse.json').read_text())
        print(f'{name}: {sparse["registered"]}/{sparse["total"]} keyframes registered', flush=True)
        base_seconds = None
        for label, sets in variants:
            out = args.root / f'{name}_{args.tag}{label}'
            settings, seconds = run_variant(work, out, sets)
            base_seconds = base_seconds or seconds
            fig = evaluate(out, truth_folder(bag))
            line = (
                f'  {label:12s} rock surface median {100 * fig["rock_median_rel_b"]:5.2f} % of b '
                f'({1000 * fig["rock_median_distance_m"]:.2f} mm), p90 '
                f'{100 * fig["rock_p90_rel_b"]:5.2f} %; dense+mesh {seconds:6.1f} s '
                f'(x{seconds / base_seconds:.2f})'
            )
            if args.true_poses:
                true = true_pose_figures(
                    out, truth_folder(bag), settings.recon.dense, settings.recon.poisson,
                    settings.recon.crop_radius,
                )  # fmt: skip
                line += (
                    '\n    true poses: pair depth bias rock '
                    f'{100 * true["pair_rock_median_rel_depth"]:+.3f} % (MAD '
                    f'{100 * true["pair_rock_mad_rel_depth"]:.3f} %), ground '
                    f'{100 * true["pair_ground_median_rel_depth"]:+.3f} %; fused points on rocks '
                    f'{100 * true["cloud_rock_median_rel_b"]:.2f} % of b; Poisson mesh '
                    f'{100 * true["mesh_rock_median_rel_b"]:.2f} % of b'
                )
            print(line, flush=True)


if __name__ == '__main__':
    main()
