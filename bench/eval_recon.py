"""Score a reconstruction work folder against the simulator's truth (prints figures).

    .venv/bin/python bench/eval_recon.py WORK_DIR BAG_truth [--json OUT]

Figures: registered keyframes, camera centre error after a similarity alignment to the true
cameras (paired by stamp; rotation from the camera orientations, so that a straight path is
aligned too; scale and shift from the centres; relative to the pile extent), scale error of the
claimed metric frame (the alignment's scale should be 1) and of the target and odometry estimates
alone, and the distance from the mesh to the true surface (median, relative to the median rock b):
over the mesh within the pile's footprint, and over the mesh whose nearest true surface is a rock
(``rock_*``: area-weighted, the surface every rock size is measured on).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import open3d as o3d
from scipy.spatial.transform import Rotation

from stockpile_ros.geometry import Similarity
from stockpile_ros.meshio import LabelledMesh, read_labelled_mesh
from stockpile_ros.tools.evaluation.match import transfer_labels

F64 = npt.NDArray[np.float64]


def weighted_quantile(values: F64, weights: F64, q: float) -> float:
    """The value below which the share ``q`` of the total weight lies."""
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cumulative, q * cumulative[-1])])


def rock_surface_distance(
    vertices: F64, faces: npt.NDArray[np.int64], scene: LabelledMesh, b: float
) -> dict[str, float]:
    """Area-weighted distance to the true surface of the mesh parts whose nearest surface is a rock.

    Faces are cut into pieces no longer than a twentieth of ``b`` first, so that a large face
    does not take one distance for all of its area.

    Returns:
        Median and 90th percentile distance [m] and relative to ``b``, and the share of the
        mesh's area that lies on rocks.

    """
    transfer = transfer_labels(vertices, faces, scene, np.inf, max_edge=b / 20)
    rock = transfer.true_labels > 0
    dist, area = transfer.distances[rock], transfer.areas[rock]
    median = weighted_quantile(dist, area, 0.5)
    p90 = weighted_quantile(dist, area, 0.9)
    return {
        'rock_median_distance_m': median,
        'rock_p90_distance_m': p90,
        'rock_median_rel_b': median / b,
        'rock_p90_rel_b': p90 / b,
        'rock_area_share': float(area.sum() / transfer.areas.sum()),
    }


def align_keyframes(
    keyframes: list[dict[str, Any]], truth: dict[str, Any]
) -> tuple[Similarity, F64]:
    """Similarity from the keyframes' frame to the truth's, and each keyframe's centre error [m].

    Keyframes are paired with the true cameras by stamp. Centres alone leave the roll about a
    straight path free: the rotation is the chordal mean of the camera orientations'
    differences, then scale and shift come from the centres.
    """
    true_cams = {int(c['stamp_ns']): c for c in truth['cameras']}
    stamps = np.array(sorted(true_cams))
    ours, theirs, rotations = [], [], np.zeros((3, 3))
    for kf in keyframes:
        k = int(np.argmin(np.abs(stamps - kf['stamp_ns'])))
        if abs(int(stamps[k]) - kf['stamp_ns']) < 5_000_000:
            cam = true_cams[int(stamps[k])]
            ours.append(kf['position'])
            theirs.append(cam['position'])
            rotations += (
                Rotation.from_quat(cam['orientation_xyzw']).as_matrix()
                @ Rotation.from_quat(kf['orientation_xyzw']).as_matrix().T
            )
    src, dst = np.asarray(ours), np.asarray(theirs)
    u, _, vt = np.linalg.svd(rotations)
    rot = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    xs, xd = src - src.mean(axis=0), dst - dst.mean(axis=0)
    scale = float(np.sum(xd * (xs @ rot.T)) / np.sum(xs**2))
    sim = Similarity(scale, rot, dst.mean(axis=0) - scale * rot @ src.mean(axis=0))
    cam_err = np.linalg.norm(sim.apply(src) - dst, axis=1)
    return sim, cam_err


def evaluate(work: Path, truth_dir: Path) -> dict[str, Any]:
    truth = json.loads((truth_dir / 'truth.json').read_text())
    info = json.loads((work / 'mesh' / 'mesh.json').read_text())
    sparse = json.loads((work / 'sparse' / 'sparse.json').read_text())
    sim, cam_err = align_keyframes(info['keyframes'], truth)

    scene = read_labelled_mesh(truth_dir / 'scene.ply')
    rock_faces = scene.faces[scene.labels > 0]
    rock_v = scene.vertices[np.unique(rock_faces)]
    extent = float(np.max(np.ptp(rock_v[:, :2], axis=0)))
    b_median = float(np.median([r['b'] for r in truth['rocks']]))

    mesh = read_labelled_mesh(work / 'mesh' / 'mesh.ply')
    verts = sim.apply(mesh.vertices)
    legacy = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(scene.vertices), o3d.utility.Vector3iVector(scene.faces)
    )
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(legacy))
    dist = rc.compute_distance(o3d.core.Tensor(verts.astype(np.float32))).numpy()
    lo, hi = rock_v.min(axis=0) - 0.1, rock_v.max(axis=0) + 0.1
    in_pile = np.all((verts[:, :2] >= lo[:2]) & (verts[:, :2] <= hi[:2]), axis=1)

    metric = info['scale']['method'] != 'none'
    out: dict[str, Any] = {
        'registered': f'{sparse["registered"]}/{sparse["total"]}',
        'registered_fraction': sparse['registered_fraction'],
        'reprojection_px': sparse['mean_reprojection_error_px'],
        'pile_extent_m': extent,
        'camera_error_max_rel_extent': float(cam_err.max() / extent),
        'camera_error_rms_rel_extent': float(np.sqrt(np.mean(cam_err**2)) / extent),
        'scale_method': info['scale']['method'],
        'scale_rel_uncertainty': info['scale']['rel_uncertainty'],
        'median_rock_b_m': b_median,
        'mesh_median_distance_m': float(np.median(dist)),
        'mesh_pile_median_distance_m': float(np.median(dist[in_pile])) if in_pile.any() else None,
        'mesh_pile_p90_distance_m': float(np.percentile(dist[in_pile], 90))
        if in_pile.any()
        else None,
        'mesh_pile_median_rel_b': float(np.median(dist[in_pile]) / b_median)
        if in_pile.any()
        else None,
        'mesh_faces': len(mesh.faces),
        **rock_surface_distance(verts, mesh.faces, scene, b_median),
    }
    if metric:
        combined = info['scale']['metres_per_unit']
        out['scale_error'] = sim.scale - 1.0
        for key in ('target', 'odometry'):
            est = info.get('scale_details', {}).get(key, {}).get('estimate')
            if est:
                out[f'scale_error_{key}'] = est['metres_per_unit'] / (combined * sim.scale) - 1.0
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('work', type=Path)
    parser.add_argument('truth', type=Path)
    parser.add_argument('--json', type=Path)
    args = parser.parse_args()
    figures = evaluate(args.work, args.truth)
    for key, value in figures.items():
        print(f'{key:32s} {value:.5g}' if isinstance(value, float) else f'{key:32s} {value}')
    if args.json:
        args.json.write_text(json.dumps(figures, indent=1) + '\n')


if __name__ == '__main__':
    main()
