"""Benchmark of the mesh segmentation (issue 5).

1. Speed: a ~1 M-face Poisson mesh of a synthetic pile, segmented in ``paper`` mode on one core
   (vectorised search vs. the per-face Python reference BFS), labels checked identical.
2. Quality: mean rock recall / precision of ``paper`` and ``default`` modes against the known
   labels, and per-rock errors of b and volume, on synthetic piles or on the simulator's scene.ply.

Times are CPU seconds of this process (``time.process_time``): on one thread they are the wall
time of an idle machine, and other work sharing the cores does not inflate them.

Usage:
    .venv/bin/python bench/bench_segment.py                       # synthetic pile
    .venv/bin/python bench/bench_segment.py --scene SIM_truth     # simulator truth folder(s)
"""

from __future__ import annotations

import os

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ[_var] = '1'

import argparse  # noqa: E402
import json  # noqa: E402
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
    args = parser.parse_args()
    if not args.scene:
        pile = make_pile(24, seed=22, spread=0.25, density=40000, noise=args.noise)
        v, f = poisson_mesh(pile.points, pile.normals, depth=args.depth)
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
