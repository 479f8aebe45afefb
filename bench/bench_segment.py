"""Benchmark of the mesh segmentation (issue 5).

1. Speed: a ~1 M-face Poisson mesh of a synthetic pile, segmented in ``paper`` mode on one core
   (vectorised search vs. the per-face Python reference BFS), labels checked identical.
2. Quality: mean rock recall / precision of ``paper`` and ``default`` modes against the known
   labels, and per-rock errors of b and volume, on synthetic piles or on the simulator's scene.ply.

3. With ``--against REV``: ``segment_mesh`` of this code and of commit REV (the code the speed
   targets were set against is the parent of 4ac1a14) on the synthetic pile, alternated in this
   one process ``--runs`` times per mode, best and median of each and their ratios, and how many
   faces of paper mode's regions moved between the two. This machine's speed moves by more than
   the targets' margins from hour to hour, so only ratios taken in one run compare.

Times are CPU seconds of this process (``time.process_time``): on one thread they are the wall
time of an idle machine, and other work sharing the cores does not inflate them.

Usage:
    .venv/bin/python bench/bench_segment.py                       # synthetic pile
    .venv/bin/python bench/bench_segment.py --scene SIM_truth     # simulator truth folder(s)
    .venv/bin/python bench/bench_segment.py --against 4ac1a14^    # speed-up against a commit
"""

from __future__ import annotations

import os

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ[_var] = '1'

import argparse  # noqa: E402
import importlib  # noqa: E402
import json  # noqa: E402
import re  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from stockpile_ros.meshio import read_labelled_mesh  # noqa: E402
from stockpile_ros.segment import valleys  # noqa: E402
from stockpile_ros.segment.adjacency import face_adjacency, face_geometry  # noqa: E402
from stockpile_ros.segment.criterion import edge_scores  # noqa: E402
from stockpile_ros.segment.measure import MeasureParams, measure_rocks  # noqa: E402
from stockpile_ros.segment.params import SegmentParams  # noqa: E402
from stockpile_ros.segment.region import grow_regions  # noqa: E402
from stockpile_ros.segment.segmentation import segment_mesh  # noqa: E402
from stockpile_ros.segment.valleys import valley_depths  # noqa: E402
from stockpile_ros.tools.reference_bfs import reference_bfs  # noqa: E402
from stockpile_ros.tools.scoring import rock_recall_precision  # noqa: E402
from stockpile_ros.tools.synthetic import (  # noqa: E402
    make_pile,
    poisson_mesh,
    sample_scene,
    truth_face_labels,
)


def best_of(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.process_time()
        fn()
        times.append(time.process_time() - t)
    return min(times)


def speed(v: np.ndarray, f: np.ndarray, repeat: int, reference: bool) -> None:
    print(f'mesh: {len(f)} faces, {len(v)} vertices')
    params = SegmentParams.paper()
    total = best_of(lambda: segment_mesh(v, f, params), repeat)
    g = face_geometry(v, f)
    adj = face_adjacency(f, len(v))
    t_geom = best_of(lambda: face_geometry(v, f), repeat)
    t_adj = best_of(lambda: face_adjacency(f, len(v)), repeat)
    t_score = best_of(lambda: edge_scores(g.centroids, g.normals, adj.i, adj.j), repeat)
    fwd, back = edge_scores(g.centroids, g.normals, adj.i, adj.j)
    t = params.threshold
    seeds = np.arange(len(f))
    t_grow = best_of(lambda: grow_regions(adj.across_sides(fwd > t, back > t), seeds), repeat)
    fast = grow_regions(adj.across_sides(fwd > t, back > t), seeds)
    print(f'paper mode, one core, best of {repeat}: total {total:.2f} s '
          f'(geometry {t_geom:.2f}, adjacency {t_adj:.2f}, Eq. 2 on all edges {t_score:.2f}, '
          f'search {t_grow:.2f}); {fast.max()} regions')  # fmt: skip
    d = SegmentParams()
    t_default = best_of(lambda: segment_mesh(v, f, d), repeat)
    fast_default = segment_mesh(v, f, d)
    scale = fast_default.scale
    # The baseline in the same run: every valley radius smoothed on the mesh itself, as before
    # the coarse graph (valleys.COARSE_MIN_EDGES).
    coarse_min = valleys.COARSE_MIN_EDGES
    valleys.COARSE_MIN_EDGES = float('inf')
    t_mesh = best_of(lambda: segment_mesh(v, f, d), repeat)
    same = np.array_equal(segment_mesh(v, f, d).labels, fast_default.labels)
    valleys.COARSE_MIN_EDGES = coarse_min
    print(
        f'default mode, valleys smoothed on the mesh alone: {t_mesh:.2f} s; with the coarse '
        f'graph {t_default:.2f} s, ratio {t_mesh / t_default:.2f}x, labels identical: {same}'
    )
    radii = [scale.valley_radius, scale.split_radius]
    t_valley = best_of(lambda: valley_depths(v, f, g, radii, scale.edge, adj.vertex_edges), repeat)
    print(f'default mode, one core, best of {repeat}: total {t_default:.2f} s '
          f'(median edge {scale.edge * 1000:.2f} mm, smallest rock {scale.min_rock_b * 1000:.0f} '
          f'mm; '
          f'valley depths at {radii[0] * 1000:.1f} and {radii[1] * 1000:.1f} mm: '
          f'{t_valley:.2f})')  # fmt: skip
    if reference:
        t0 = time.process_time()
        slow = reference_bfs(g.centroids, g.normals, adj, t, seeds)
        t_ref = time.process_time() - t0
        print(f'reference per-face BFS: {t_ref:.2f} s (search only); search ratio '
              f'{t_ref / t_grow:.1f}x, ratio against the whole vectorised segmentation '
              f'{t_ref / total:.1f}x; labels identical: {np.array_equal(fast, slow)}')  # fmt: skip


def older_code(rev: str, folder: Path):
    """Return ``segment_mesh`` and ``SegmentParams`` of commit ``rev``, importable beside ours.

    The package at ``rev`` is written under ``folder`` as ``stockpile_ros_then`` (its own
    imports renamed), so that both run in this process on the same mesh.
    """
    root = Path(__file__).resolve().parents[1]
    name = 'stockpile_ros_then'
    archive = subprocess.run(
        ['git', 'archive', '--format=tar', rev, 'stockpile_ros'], cwd=root, capture_output=True,
        check=True,
    ).stdout  # fmt: skip
    subprocess.run(['tar', '-x', '-C', str(folder)], input=archive, check=True)
    package = folder / name
    (folder / 'stockpile_ros').rename(package)
    for source in package.rglob('*.py'):
        source.write_text(re.sub(r'\bstockpile_ros\b', name, source.read_text()))
    sys.path.insert(0, str(folder))
    segmentation = importlib.import_module(f'{name}.segment.segmentation')
    try:
        params = importlib.import_module(f'{name}.segment.params').SegmentParams
    except ModuleNotFoundError:  # before the parameters had a module of their own
        params = segmentation.SegmentParams
    return segmentation.segment_mesh, params


def faces_moved(a: np.ndarray, b: np.ndarray) -> int:
    """Count the faces outside the pairs of regions of ``a`` and ``b`` that overlap most."""
    pair, count = np.unique(np.stack([a, b]), axis=1, return_counts=True)
    best_a = np.zeros(int(a.max()) + 1, dtype=np.int64)
    best_b = np.zeros(int(b.max()) + 1, dtype=np.int64)
    np.maximum.at(best_a, pair[0], count)
    np.maximum.at(best_b, pair[1], count)
    mutual = (count == best_a[pair[0]]) & (count == best_b[pair[1]])
    return int(count[~mutual].sum())


def against(v: np.ndarray, f: np.ndarray, rev: str, runs: int) -> None:
    with tempfile.TemporaryDirectory() as folder:
        old_segment, old_params = older_code(rev, Path(folder))
        for mode in ('paper', 'default'):
            new_p, old_p = SegmentParams.preset(mode), old_params.preset(mode)
            labels = segment_mesh(v, f, new_p).labels, old_segment(v, f, old_p).labels
            times: tuple[list[float], list[float]] = ([], [])
            for _ in range(runs):
                for k, (segment, p) in enumerate(((segment_mesh, new_p), (old_segment, old_p))):
                    t = time.process_time()
                    segment(v, f, p)
                    times[k].append(time.process_time() - t)
            new, old = (np.array(x) for x in times)
            print(f'{mode} mode against {rev}, {runs} alternated runs: best {new.min():.3f} s '
                  f'against {old.min():.3f} s ({old.min() / new.min():.2f} times), median '
                  f'{np.median(new):.3f} s against {np.median(old):.3f} s '
                  f'({np.median(old) / np.median(new):.2f} times); {labels[0].max()} regions '
                  f'against {labels[1].max()}, {faces_moved(*labels)} faces moved')  # fmt: skip


def quality(name: str, v, f, points, point_labels, truth_rocks: dict | None) -> None:
    g = face_geometry(v, f)
    truth = truth_face_labels(g.centroids, points, point_labels)
    for mode in ('paper', 'default'):
        seg = segment_mesh(v, f, SegmentParams.preset(mode))
        r, p, rr, pp = rock_recall_precision(truth, seg.labels, g.areas)
        line = f'{name} {mode:7s}: mean rock recall {r:.3f} precision {p:.3f} '
        line += f'(worst {rr.min():.2f} / {pp.min():.2f}), {seg.labels.max()} segments'
        if truth_rocks and mode == 'default':
            for comp in ('auto', 'hull', 'mirror', 'ground'):
                eb, ev = [], []
                for rock in measure_rocks(v, seg, MeasureParams(completion=comp)):
                    sel = seg.labels == rock.id
                    w = np.bincount(truth[sel], weights=g.areas[sel])
                    w[0] = 0
                    k = int(np.argmax(w))
                    if k in truth_rocks:
                        eb.append(rock.b / truth_rocks[k]['b'] - 1)
                        ev.append(rock.volume / truth_rocks[k]['volume'] - 1)
                b_err, v_mape = np.median(np.abs(eb)), np.mean(np.abs(ev))
                line += f'\n    completion {comp:6s}: b median |err| {b_err:.3f}, '
                line += f'volume MAPE {v_mape:.3f} (median err {np.median(ev):+.3f})'
        print(line)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--scene', nargs='*', type=Path, default=[], help='simulator truth folders')
    parser.add_argument('--depth', type=int, default=9, help='Poisson depth')
    parser.add_argument('--noise', type=float, default=0.0, help='point noise [m]')
    parser.add_argument('--repeat', type=int, default=3)
    parser.add_argument('--no-reference', action='store_true')
    parser.add_argument('--against', metavar='REV', help='time against this commit alone')
    parser.add_argument('--runs', type=int, default=20, help='alternated runs with --against')
    args = parser.parse_args()
    if not args.scene:
        pile = make_pile(24, seed=22, spread=0.25, density=40000, noise=args.noise)
        v, f = poisson_mesh(pile.points, pile.normals, depth=args.depth)
        if args.against:
            against(v, f, args.against, args.runs)
            return
        truth = {k + 1: {'b': 2 * float(np.sort(r.semi_axes)[1]), 'volume': r.volume()}
                 for k, r in enumerate(pile.rocks)}  # fmt: skip
        speed(v, f, args.repeat, not args.no_reference)
        quality('synthetic', v, f, pile.points, pile.labels, truth)
        return
    ang = np.radians(np.arange(0, 360, 30))
    eyes = np.column_stack([1.5 * np.cos(ang), 1.5 * np.sin(ang), np.full(len(ang), 1.1)])
    eyes = np.vstack([eyes, [[0.0, 0.0, 2.0]]])
    for folder in args.scene:
        scene = read_labelled_mesh(folder / 'scene.ply')
        rocks = {r['id']: r for r in json.loads((folder / 'truth.json').read_text())['rocks']}
        pile = sample_scene(scene.vertices, scene.faces, scene.labels, 60000, viewpoints=eyes)
        pts = pile.points + np.random.default_rng(0).normal(
            scale=args.noise, size=pile.points.shape
        )
        v, f = poisson_mesh(pts, pile.normals, depth=args.depth)
        print(f'{folder}: {len(f)} faces (points seen from 13 viewpoints, noise {args.noise} m)')
        if folder == args.scene[0]:
            speed(v, f, args.repeat, not args.no_reference)
        quality(folder.name, v, f, pts, pile.labels, rocks)


if __name__ == '__main__':
    main()
