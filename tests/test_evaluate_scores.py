"""`stockpile evaluate` on small synthetic truths and results built here.

The scene: five rocks in a row on a ground grid (boxes and ellipsoids, sunk 17.3 mm into the ground
so that no rock face lies in the ground plane), rock 5 barely visible. Results are the truth's
own mesh and figures, moved, scaled, relabelled or cut down.
"""

from __future__ import annotations

import copy
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import open3d as o3d
import pytest
from scipy.spatial.transform import Rotation
from segment_fixtures import make_report

from stockpile_ros.artefacts import KeyframePose, ScaleRecord, save
from stockpile_ros.cli import main
from stockpile_ros.meshio import LabelledMesh, read_labelled_mesh, write_labelled_mesh
from stockpile_ros.result import RockRecord
from stockpile_ros.tools.evaluation import (
    EvaluationError,
    EvaluationOptions,
    MatchOptions,
    evaluate,
)

SINK = 0.0173
FPS_NS = 33_333_333
# id: (shape, size, x, visible_fraction); sizes are box edges or ellipsoid semi-axes.
ROCKS = {
    1: ('box', (0.30, 0.20, 0.12), 0.0, 0.8),
    2: ('ellipsoid', (0.15, 0.11, 0.08), 0.5, 0.7),
    3: ('box', (0.16, 0.12, 0.10), 1.0, 0.6),
    4: ('ellipsoid', (0.10, 0.09, 0.07), 1.5, 0.5),
    5: ('box', (0.08, 0.06, 0.05), 2.0, 0.1),
}


def _rock_mesh(shape: str, size: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Closed mesh with outward faces, centred at the origin."""
    if shape == 'box':
        m = o3d.geometry.TriangleMesh.create_box(*size).subdivide_midpoint(2)
        v = np.asarray(m.vertices) - np.array(size) / 2
    else:
        m = o3d.geometry.TriangleMesh.create_icosahedron(1.0).subdivide_midpoint(2)
        v = np.asarray(m.vertices)
        v = v / np.linalg.norm(v, axis=1, keepdims=True) * np.array(size)
    return v, np.asarray(m.triangles, dtype=np.int64)


def _volume(v: np.ndarray, f: np.ndarray) -> float:
    return float(np.einsum('ij,ij->i', v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6)


def _ground() -> tuple[np.ndarray, np.ndarray]:
    xs, ys = np.linspace(-0.53, 2.57, 15), np.linspace(-0.71, 0.93, 9)
    gx, gy = np.meshgrid(xs, ys, indexing='ij')
    v = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    idx = np.arange(gx.size).reshape(gx.shape)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    f = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    return v, f


def _look_at(centre: np.ndarray, target: np.ndarray) -> np.ndarray:
    forward = (target - centre) / np.linalg.norm(target - centre)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(forward, right), forward], axis=1)


@dataclass
class Truth:
    path: Path
    data: dict[str, Any]
    mesh: LabelledMesh


def _gradation_d50(rocks: list[dict[str, Any]]) -> float:
    """Mass-weighted median of b: a stand-in consistent between truth and report."""
    order = sorted(rocks, key=lambda r: r['b'])
    mass = np.cumsum([r['mass'] for r in order])
    return float(order[int(np.searchsorted(mass, mass[-1] / 2))]['b'])


def make_truth(root: Path, collinear: bool = False) -> Truth:
    verts, faces, labels, rocks = [], [], [], []
    gv, gf = _ground()
    verts.append(gv)
    faces.append(gf)
    labels.append(np.zeros(len(gf), dtype=np.int32))
    offset = len(gv)
    for rid, (shape, size, x, vf) in ROCKS.items():
        v, f = _rock_mesh(shape, size)
        height = size[2] if shape == 'box' else 2 * size[2]
        v = v + np.array([x, 0.0, height / 2 - SINK])
        vol = _volume(v, f)
        ext = v.max(axis=0) - v.min(axis=0)
        a, b, c = sorted(ext.tolist(), reverse=True)
        rocks.append(
            {
                'id': rid,
                'centroid': v.mean(axis=0).tolist(),
                'a': a,
                'b': b,
                'c': c,
                'esd': (6 * vol / np.pi) ** (1 / 3),
                'volume': vol,
                'mass': vol * 2650.0,
                'area': 0.0,
                'visible_fraction': vf,
            }
        )
        verts.append(v)
        faces.append(f + offset)
        labels.append(np.full(len(f), rid, dtype=np.int32))
        offset += len(v)
    mesh = LabelledMesh(np.concatenate(verts), np.concatenate(faces), np.concatenate(labels))
    n = 40
    if collinear:
        centres = np.stack([np.linspace(-0.5, 2.5, n), np.full(n, -1.5), np.full(n, 1.0)], 1)
        targets = centres + np.array([0.0, 1.5, -1.0])
    else:
        ang = np.linspace(-2.4, -0.7, n)
        centres = np.stack([1 + 2 * np.cos(ang), 2 * np.sin(ang), np.full(n, 1.2)], axis=1)
        targets = np.tile([1.0, 0.0, 0.0], (n, 1))
    cameras = [
        {
            'stamp_ns': 1_700_000_000_000_000_000 + i * FPS_NS,
            'position': c.tolist(),
            'orientation_xyzw': Rotation.from_matrix(_look_at(c, tg)).as_quat().tolist(),
        }
        for i, (c, tg) in enumerate(zip(centres, targets, strict=True))
    ]
    data = {
        'schema': 'stockpile-truth/1',
        'units': 'm',
        'frame_id': 'odom',
        'seed': 0,
        'scene': {},
        'camera': {},
        'cameras': cameras,
        'target': None,
        'specific_gravity': 2.65,
        'rocks': rocks,
        'gradation': {'d50': _gradation_d50(rocks)},
    }
    folder = root / 'truth'
    folder.mkdir()
    (folder / 'truth.json').write_text(json.dumps(data))
    write_labelled_mesh(folder / 'scene.ply', mesh)
    return Truth(folder, data, read_labelled_mesh(folder / 'scene.ply'))


@pytest.fixture
def truth(tmp_path: Path) -> Truth:
    return make_truth(tmp_path)


def make_result(
    root: Path,
    truth: Truth,
    name: str,
    *,
    scale: float = 1.0,
    rotation: np.ndarray | None = None,
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0),
    method: str = 'target',
    labels: np.ndarray | None = None,
    rocks: list[dict[str, Any]] | None = None,
    mesh_shift: tuple[float, float, float] = (0.0, 0.0, 0.0),
    keyframe_step: int = 3,
    frame_id: str = 'stockpile',
    noise: float = 0.0,
    stamp_offset_ns: int = 0,
) -> Path:
    """Write a result that is the truth seen in a frame where x_truth maps to s R x + t.

    Rock figures are multiplied by ``scale`` (lengths) and its cube (volume), as a reconstruction
    off by that scale would report them.
    """
    rot = np.eye(3) if rotation is None else rotation
    t = np.asarray(translation)
    jitter = np.random.default_rng(0).normal(scale=noise, size=truth.mesh.vertices.shape)
    moved = scale * (truth.mesh.vertices + jitter + np.asarray(mesh_shift)) @ rot.T + t
    out_rocks = [
        RockRecord(
            id=r['id'],
            centroid=(scale * rot @ np.asarray(r['centroid']) + t).tolist(),
            orientation_xyzw=[0.0, 0.0, 0.0, 1.0],
            a=scale * r['a'],
            b=scale * r['b'],
            c=scale * r['c'],
            esd=scale * r['esd'],
            volume=scale**3 * r['volume'],
            mass=r['mass'],
            visible_area=r['area'],
            visible_fraction=r['visible_fraction'],
            fer=r['a'] / r['c'],
            sphericity=1.0,
            confidence=1.0,
        )
        for r in (truth.data['rocks'] if rocks is None else rocks)
    ]
    keyframes = []
    for cam in truth.data['cameras'][::keyframe_step]:
        r_cam = Rotation.from_quat(cam['orientation_xyzw']).as_matrix()
        keyframes.append(
            KeyframePose(
                stamp_ns=cam['stamp_ns'] + stamp_offset_ns,
                position=(scale * rot @ np.asarray(cam['position']) + t).tolist(),
                orientation_xyzw=Rotation.from_matrix(rot @ r_cam).as_quat().tolist(),
            )
        )
    report = make_report(
        out_rocks,
        ScaleRecord(method),
        keyframes,
        frame_id,
        d50=truth.data['gradation']['d50'] * scale,
    )
    folder = root / name
    folder.mkdir()
    save(report, folder / 'report.json')
    lab = truth.mesh.labels if labels is None else labels
    write_labelled_mesh(folder / 'segments.ply', LabelledMesh(moved, truth.mesh.faces, lab))
    return folder


ROTATION = Rotation.from_euler('zx', [30.0, 10.0], degrees=True).as_matrix()


def _rock_errors(ev: dict[str, Any], q: str) -> list[float]:
    return [r['relative_error'][q] for r in ev['sizes']['rocks']]


def _assert_all_detected(ev: dict[str, Any]) -> None:
    det = ev['detection']
    assert (det['precision'], det['recall']) == (1.0, 1.0)
    assert (det['precision_visible'], det['recall_visible']) == (1.0, 1.0)
    assert det['missed'] == det['missed_hidden'] == det['false'] == []
    assert det['merges'] == det['splits'] == []
    assert [(m['result_id'], m['true_id']) for m in det['matches']] == [(i, i) for i in ROCKS]
    assert [m['iou'] for m in det['matches']] == pytest.approx([1.0] * 5, abs=1e-9)


def test_truth_fed_in_as_result_is_perfect(tmp_path: Path, truth: Truth) -> None:
    ev = evaluate(make_result(tmp_path, truth, 'same'), truth.path)
    assert ev['schema'] == 'stockpile-evaluation/1'
    al = ev['alignment']
    assert (al['method'], al['keyframes'], al['matched_keyframes']) == ('umeyama', 14, 14)
    assert al['scale'] == pytest.approx(1.0, abs=1e-12)
    assert al['rotation_deg'] == pytest.approx(0.0, abs=1e-6)
    assert al['centre_rmse_m'] == pytest.approx(0.0, abs=1e-12)
    assert al['orientation_median_deg'] == pytest.approx(0.0, abs=1e-6)
    assert ev['scale']['abs_error'] == pytest.approx(0.0, abs=1e-12)
    assert ev['scale']['metric'] is True
    _assert_all_detected(ev)
    assert ev['detection']['off_surface_area_share'] == 0.0
    for q in ('a', 'b', 'c', 'volume'):
        assert _rock_errors(ev, q) == [0.0] * 5
        assert ev['sizes']['summary'][q]['median_abs_pct'] == 0.0
    assert ev['sizes']['volume_mape_pct'] == 0.0
    assert [r['centroid_error_m'] for r in ev['sizes']['rocks']] == pytest.approx([0] * 5, abs=1e-9)
    assert ev['gradation']['d50_error'] == 0.0
    json.dumps(ev, allow_nan=False)


def test_rigidly_moved_result_with_its_trajectory_is_perfect(tmp_path: Path, truth: Truth) -> None:
    result = make_result(tmp_path, truth, 'moved', rotation=ROTATION, translation=(5, -2, 0.3))
    ev = evaluate(result, truth.path)
    assert ev['alignment']['rotation_deg'] == pytest.approx(31.5, abs=0.1)
    assert ev['alignment']['centre_rmse_m'] == pytest.approx(0.0, abs=1e-9)
    assert ev['scale']['abs_error'] == pytest.approx(0.0, abs=1e-12)
    _assert_all_detected(ev)
    for q in ('a', 'b', 'c', 'volume'):
        assert _rock_errors(ev, q) == [0.0] * 5


def test_noisy_surface_and_late_stamps_still_match(tmp_path: Path, truth: Truth) -> None:
    result = make_result(
        tmp_path, truth, 'noisy', rotation=ROTATION, noise=0.003, stamp_offset_ns=2_000_000
    )
    ev = evaluate(result, truth.path)
    assert ev['alignment']['matched_keyframes'] == 14
    assert ev['alignment']['centre_rmse_m'] == pytest.approx(0.0, abs=1e-9)
    det = ev['detection']
    assert (det['precision'], det['recall']) == (1.0, 1.0)
    assert det['missed'] == det['false'] == det['merges'] == det['splits'] == []
    # 3 mm of noise on 5-30 cm rocks blurs the contact lines with the ground a little.
    assert min(m['iou'] for m in det['matches']) > 0.9
    assert det['off_surface_area_share'] == 0.0


def test_straight_pass_is_aligned_with_the_orientations(tmp_path: Path) -> None:
    truth = make_truth(tmp_path, collinear=True)
    result = make_result(tmp_path, truth, 'moved', rotation=ROTATION, translation=(1, 2, 3))
    ev = evaluate(result, truth.path)
    assert ev['alignment']['method'] == 'centres+orientations'
    assert ev['alignment']['centre_rmse_m'] == pytest.approx(0.0, abs=1e-9)
    _assert_all_detected(ev)


def test_rocks_shifted_against_their_cameras_lose_every_match(tmp_path: Path, truth: Truth) -> None:
    result = make_result(tmp_path, truth, 'shifted', rotation=ROTATION, mesh_shift=(0, 0.5, 0))
    ev = evaluate(result, truth.path)
    # The trajectory still aligns perfectly: only the rocks moved.
    assert ev['alignment']['centre_rmse_m'] == pytest.approx(0.0, abs=1e-9)
    det = ev['detection']
    assert det['detected'] == 0
    assert (det['precision'], det['recall'], det['recall_visible']) == (0.0, 0.0, 0.0)
    assert det['missed'] == [1, 2, 3, 4]
    assert det['missed_hidden'] == [5]
    assert [f['id'] for f in det['false']] == [1, 2, 3, 4, 5]
    assert {f['lies_on'] for f in det['false']} <= {'off-surface', 'ground'}
    assert det['off_surface_area_share'] > 0.1
    assert ev['sizes']['rocks'] == []
    assert ev['sizes']['volume_mape_pct'] is None


def test_metric_result_five_percent_too_large(tmp_path: Path, truth: Truth) -> None:
    result = make_result(
        tmp_path, truth, 'large', scale=1.05, rotation=ROTATION, translation=(0.4, 0.1, -0.2)
    )
    ev = evaluate(result, truth.path)
    sc = ev['scale']
    assert sc['result_per_true_length'] == pytest.approx(1.05, abs=1e-12)
    assert sc['error'] == pytest.approx(0.05, abs=1e-12)
    assert sc['abs_error'] == pytest.approx(0.05, abs=1e-12)
    assert sc['sizes_rescaled'] is False
    _assert_all_detected(ev)
    for q in ('a', 'b', 'c'):
        assert _rock_errors(ev, q) == pytest.approx([0.05] * 5, abs=1e-12)
        assert ev['sizes']['summary'][q]['median_abs_pct'] == pytest.approx(5.0, abs=1e-9)
        assert ev['sizes']['summary'][q]['mean_pct'] == pytest.approx(5.0, abs=1e-9)
        # Rock 5 is 10 % visible: counted in the summary, not in the one over visible rocks.
        assert ev['sizes']['summary'][q]['n'] == 5
        assert ev['sizes']['summary_visible'][q]['n'] == 4
    assert _rock_errors(ev, 'volume') == pytest.approx([1.05**3 - 1] * 5, abs=1e-12)
    assert ev['sizes']['volume_mape_pct'] == pytest.approx(15.7625, abs=1e-9)
    assert ev['gradation']['d50_error'] == pytest.approx(0.05, abs=1e-12)
    # Matching is unaffected by the scale error: the result is aligned with its scale.
    assert ev['alignment']['centre_rmse_m'] == pytest.approx(0.0, abs=1e-9)


def test_unscaled_result_is_rescaled_not_judged(tmp_path: Path, truth: Truth) -> None:
    result = make_result(tmp_path, truth, 'unscaled', scale=0.37, method='none')
    ev = evaluate(result, truth.path)
    sc = ev['scale']
    assert (sc['metric'], sc['error'], sc['abs_error'], sc['sizes_rescaled']) == (
        False,
        None,
        None,
        True,
    )
    assert sc['result_per_true_length'] == pytest.approx(0.37, abs=1e-12)
    assert ev['sizes']['length_factor'] == pytest.approx(1 / 0.37, rel=1e-12)
    _assert_all_detected(ev)
    for q in ('a', 'b', 'c', 'volume'):
        assert _rock_errors(ev, q) == pytest.approx([0.0] * 5, abs=1e-12)
    assert ev['gradation']['d50_error'] == pytest.approx(0.0, abs=1e-12)
    # The run's smallest rock of interest, in its own units, is read in truth metres.
    interest = ev['detection']['of_interest']
    assert (interest['source'], interest['min_b_m']) == ('report', pytest.approx(0.1 / 0.37))


def test_merged_rocks_cost_recall_and_count_as_a_merge(tmp_path: Path, truth: Truth) -> None:
    labels = truth.mesh.labels.copy()
    labels[labels == 3] = 2
    rocks = [r for r in truth.data['rocks'] if r['id'] != 3]
    result = make_result(tmp_path, truth, 'merged', rotation=ROTATION, labels=labels, rocks=rocks)
    det = evaluate(result, truth.path)['detection']
    assert det['merges'] == [{'result_id': 2, 'true_ids': [2, 3]}]
    assert det['splits'] == []
    assert det['detected'] == 4
    assert det['recall'] == pytest.approx(4 / 5)
    assert det['recall_visible'] == pytest.approx(3 / 4)
    assert (det['precision'], det['precision_visible']) == (1.0, 1.0)
    assert det['missed'] == [3]
    assert det['false'] == []
    iou = {m['true_id']: m['iou'] for m in det['matches']}
    assert 0.5 < iou[2] < 1.0


def test_split_rock_costs_precision_and_counts_as_a_split(tmp_path: Path, truth: Truth) -> None:
    mesh = truth.mesh
    centroids = mesh.vertices[mesh.faces].mean(axis=1)
    labels = mesh.labels.copy()
    labels[(labels == 1) & (centroids[:, 0] > 0.06)] = 7
    piece = copy.deepcopy(truth.data['rocks'][0])
    piece['id'] = 7
    rocks = [*truth.data['rocks'], piece]
    result = make_result(tmp_path, truth, 'split', labels=labels, rocks=rocks)
    det = evaluate(result, truth.path)['detection']
    assert det['splits'] == [{'true_id': 1, 'result_ids': [1, 7]}]
    assert det['merges'] == []
    assert det['detected'] == 5
    assert (det['recall'], det['recall_visible']) == (1.0, 1.0)
    assert det['precision'] == pytest.approx(5 / 6)
    assert det['precision_visible'] == pytest.approx(4 / 5)
    assert det['false'] == [{'id': 7, 'lies_on': 'rock 1'}]


def test_pieces_of_a_barely_visible_rock_count_neither_way(tmp_path: Path, truth: Truth) -> None:
    mesh = truth.mesh
    centroids = mesh.vertices[mesh.faces].mean(axis=1)
    labels = mesh.labels.copy()
    five = labels == 5
    labels[five & (centroids[:, 0] > np.median(centroids[five, 0]))] = 7
    piece = copy.deepcopy(truth.data['rocks'][4])
    piece['id'] = 7
    rocks = [*truth.data['rocks'], piece]
    result = make_result(tmp_path, truth, 'hidden-split', labels=labels, rocks=rocks)
    det = evaluate(result, truth.path)['detection']
    assert [f['lies_on'] for f in det['false']] == ['rock 5']
    assert det['precision'] == pytest.approx(5 / 6)
    assert (det['precision_visible'], det['recall_visible']) == (1.0, 1.0)


def test_rocks_under_the_smallest_rock_of_interest_are_left_aside(
    tmp_path: Path, truth: Truth
) -> None:
    # Rocks 3, 4 and 5 (b 0.12, 0.18, 0.06 m) reported as one: a false rock among the visible
    # ones, and among the rocks of b >= 0.19 m (1 and 2) a cluster of smaller rocks.
    labels = truth.mesh.labels.copy()
    labels[np.isin(labels, [4, 5])] = 3
    rocks = [r for r in truth.data['rocks'] if r['id'] not in (4, 5)]
    result = make_result(tmp_path, truth, 'clustered', labels=labels, rocks=rocks)
    det = evaluate(result, truth.path, EvaluationOptions(min_b=0.19))['detection']
    assert (det['recall_visible'], det['precision_visible']) == (0.5, pytest.approx(2 / 3))
    interest = det['of_interest']
    assert (interest['min_b_m'], interest['source']) == (0.19, 'option')
    assert (interest['true_rocks'], interest['true_rocks_under']) == (2, 3)
    assert (interest['recall'], interest['precision']) == (1.0, pytest.approx(2 / 3))
    assert (interest['missed'], interest['clusters']) == ([], [3])
    # From the report (0.1 m): only rock 5 is under it, and the figures are the visible ones.
    det = evaluate(result, truth.path)['detection']
    interest = det['of_interest']
    assert (interest['source'], interest['min_b_m'], interest['true_rocks_under']) == (
        'report',
        0.1,
        1,
    )
    assert (interest['recall'], interest['precision']) == (
        det['recall_visible'],
        det['precision_visible'],
    )
    assert interest['missed'] == det['missed'] == [3, 4]


def test_missing_rocks_cost_recall_only_when_visible(tmp_path: Path, truth: Truth) -> None:
    labels = truth.mesh.labels.copy()
    labels[np.isin(labels, [4, 5])] = 0
    rocks = [r for r in truth.data['rocks'] if r['id'] not in (4, 5)]
    result = make_result(tmp_path, truth, 'missing', labels=labels, rocks=rocks)
    det = evaluate(result, truth.path)['detection']
    assert det['detected'] == 3
    assert det['recall'] == pytest.approx(3 / 5)
    assert det['recall_visible'] == pytest.approx(3 / 4)
    assert (det['precision'], det['precision_visible']) == (1.0, 1.0)
    assert det['missed'] == [4]
    assert det['missed_hidden'] == [5]
    assert det['false'] == det['merges'] == det['splits'] == []


def test_a_ground_patch_reported_as_a_rock_is_false(tmp_path: Path, truth: Truth) -> None:
    mesh = truth.mesh
    centroids = mesh.vertices[mesh.faces].mean(axis=1)
    labels = mesh.labels.copy()
    patch = (labels == 0) & (centroids[:, 1] > 0.4)
    labels[patch] = 9
    extra = copy.deepcopy(truth.data['rocks'][4])
    extra['id'] = 9
    result = make_result(
        tmp_path, truth, 'ground', labels=labels, rocks=[*truth.data['rocks'], extra]
    )
    det = evaluate(result, truth.path)['detection']
    assert det['false'] == [{'id': 9, 'lies_on': 'ground'}]
    assert det['precision'] == pytest.approx(5 / 6)
    assert det['recall'] == 1.0


def test_rocks_without_faces_and_faces_without_rocks(tmp_path: Path, truth: Truth) -> None:
    labels = truth.mesh.labels.copy()
    labels[labels == 4] = 8
    ghost = copy.deepcopy(truth.data['rocks'][3])
    ghost['id'] = 10
    rocks = [r for r in truth.data['rocks'] if r['id'] != 4] + [ghost]
    result = make_result(tmp_path, truth, 'unlisted', labels=labels, rocks=rocks)
    det = evaluate(result, truth.path)['detection']
    # Faces under an id the report does not list count as unassigned.
    assert det['faces_with_unlisted_ids'] == int(np.count_nonzero(truth.mesh.labels == 4))
    assert det['missed'] == [4]
    assert det['false'] == [{'id': 10, 'lies_on': 'no faces'}]
    assert (det['detected'], det['precision']) == (4, 0.8)


def test_partial_result_mesh_lowers_iou_not_detection(tmp_path: Path, truth: Truth) -> None:
    # A third of rock 1's surface left unassigned: the IoU is the share kept.
    mesh = truth.mesh
    centroids = mesh.vertices[mesh.faces].mean(axis=1)
    labels = mesh.labels.copy()
    labels[(labels == 1) & (centroids[:, 0] > 0.09)] = 0
    result = make_result(tmp_path, truth, 'partial', labels=labels)
    det = evaluate(result, truth.path)['detection']
    rock1 = mesh.labels == 1
    areas = _areas(mesh)
    kept = areas[rock1 & (labels == 1)].sum() / areas[rock1].sum()
    assert 0.5 < kept < 0.9
    assert {m['true_id']: m['iou'] for m in det['matches']}[1] == pytest.approx(kept, abs=1e-6)
    strict = evaluate(result, truth.path, EvaluationOptions(match=MatchOptions(min_iou=0.95)))
    assert strict['detection']['missed'] == [1]
    assert strict['detection']['false'] == [{'id': 1, 'lies_on': 'rock 1'}]


def _areas(mesh: LabelledMesh) -> np.ndarray:
    tri = mesh.vertices[mesh.faces]
    return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)


def test_unalignable_result_is_a_clear_error(tmp_path: Path, truth: Truth) -> None:
    result = make_result(tmp_path, truth, 'few', keyframe_step=30)
    with pytest.raises(EvaluationError, match='2 of 2 keyframes'):
        evaluate(result, truth.path)
    same = make_result(tmp_path, truth, 'few_same', keyframe_step=30, frame_id='odom')
    ev = evaluate(same, truth.path)
    assert ev['alignment']['method'] == 'identity'
    assert (ev['scale']['error'], ev['scale']['abs_error']) == (None, None)
    assert 'not measured' in ev['scale']['note']
    _assert_all_detected(ev)


def test_a_report_this_code_does_not_read_is_refused_with_where_it_is(
    tmp_path: Path, truth: Truth
) -> None:
    result = make_result(tmp_path, truth, 'old')
    path = result / 'report.json'
    data = json.loads(path.read_text())
    path.write_text(json.dumps({**data, 'schema': 'stockpile-report/2'}))
    with pytest.raises(EvaluationError, match=f'{re.escape(str(path))}: schema .* is older'):
        evaluate(result, truth.path)
    del data['rocks'][0]['b']
    path.write_text(json.dumps(data))
    with pytest.raises(EvaluationError, match=r"rocks\[0\]: 'b' missing"):
        evaluate(result, truth.path)


def test_cli_prints_a_table_and_writes_json(
    tmp_path: Path, truth: Truth, capsys: pytest.CaptureFixture[str]
) -> None:
    result = make_result(tmp_path, truth, 'large', scale=1.05)
    out = tmp_path / 'ev.json'
    assert main(['evaluate', str(result), str(truth.path / 'truth.json'), '--json', str(out)]) == 0
    text = capsys.readouterr().out
    assert 'precision 1.000, recall 1.000' in text
    assert 'rocks of interest (visible, b >= 0.1 m from the report; 1 true rocks under it' in text
    assert 'scale error +5.00 %' in text
    assert 'volume MAPE 15.76 %' in text
    ev = json.loads(out.read_text())
    assert ev['detection']['detected'] == 5
    assert sorted(p.name for p in result.iterdir()) == ['report.json', 'segments.ply']


def test_cli_reports_a_missing_folder_without_traceback(
    tmp_path: Path, truth: Truth, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(['evaluate', str(tmp_path / 'nothing'), str(truth.path)]) == 2
    err = capsys.readouterr().err
    assert 'nothing: no such result folder (one holding report.json)' in err
    assert 'Traceback' not in err
