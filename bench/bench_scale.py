"""Segmentation quality of the default mode on synthetic piles of few large and many small rocks.

Each pile is a :func:`make_pile` scene or the simulator's demo scene, meshed by Poisson (perfect
reconstruction: this judges the segmentation and the measurement alone). Per pile: the mesh's
median edge, mean rock recall and precision over the rocks at least 30 % visible, how many of them
were found (a segment with at least 80 % of its area on the rock and 80 % of the rock's area), the
median |b error| of the found ones and the D50 error (b by mass) of the measured rocks against the
visible true ones. Meshes are cached under ``--cache``.

Usage:
    .venv/bin/python bench/bench_scale.py [--piles NAME ...] [--set FIELD=VALUE ...]
"""

from __future__ import annotations

import os

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ[_var] = '1'

import argparse  # noqa: E402
import ast  # noqa: E402
import json  # noqa: E402
import pickle  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from stockpile_ros.meshio import read_labelled_mesh  # noqa: E402
from stockpile_ros.segment.gradation import gradation  # noqa: E402
from stockpile_ros.segment.measure import measure_rocks  # noqa: E402
from stockpile_ros.segment.params import SegmentParams  # noqa: E402
from stockpile_ros.segment.segmentation import segment_mesh  # noqa: E402
from stockpile_ros.tools.scoring import rock_recall_precision  # noqa: E402
from stockpile_ros.tools.synthetic import (  # noqa: E402
    make_pile,
    poisson_mesh,
    sample_scene,
    truth_face_labels,
)

# name: (make_pile arguments, Poisson depth). The first three are the 18-24-rock piles of 0.1-0.4 m
# the default mode was fitted on (bench_segment.py's pile is 'p24'); 'many' has 150 rocks of
# 5-11 cm, each under 1 % of the surface.
PILES = {
    'p24': ({'n_rocks': 24, 'seed': 22, 'spread': 0.25, 'density': 40000}, 9),
    'p18': ({'n_rocks': 18, 'seed': 5, 'spread': 0.3, 'density': 40000}, 9),
    'p20': ({'n_rocks': 20, 'seed': 11, 'spread': 0.3, 'density': 40000, 'noise': 0.001}, 9),
    'many': (
        {'n_rocks': 150, 'seed': 7, 'size': (0.04, 0.08), 'spread': 0.45, 'density': 60000,
         'max_overlap': 0.006, 'candidates': 3},
        10,
    ),
    # The same kind of pile, meshed coarser (8-20 edges across b) from points with 1 mm noise.
    'coarse': (
        {'n_rocks': 150, 'seed': 8, 'size': (0.04, 0.08), 'spread': 0.45, 'density': 40000,
         'max_overlap': 0.006, 'candidates': 3, 'noise': 0.001},
        9,
    ),
}  # fmt: skip
SPECIFIC_GRAVITY = 2.65
# The simulator's demo scene (14 rocks), sampled as seen from 13 viewpoints: 'demo'.
DEMO = Path(__file__).resolve().parents[1] / 'bags' / 'demo_truth'


def ellipsoid_area(semi: np.ndarray) -> float:
    # Knud Thomsen's approximation, within about 1 %.
    p = 1.6075
    a, b, c = semi**p
    return float(4 * np.pi * ((a * b + a * c + b * c) / 3) ** (1 / p))


def load(name: str, cache: Path):
    """Return the points, their labels, the truth per rock id (b, volume, area) and the mesh."""
    path = cache / f'{name}.pickle'
    if path.exists():
        return pickle.loads(path.read_bytes())
    if name == 'demo':
        scene = read_labelled_mesh(DEMO / 'scene.ply')
        rocks = json.loads((DEMO / 'truth.json').read_text())['rocks']
        truth = {r['id']: (r['b'], r['volume'], r['area']) for r in rocks}
        # Seen from a ring of 12 viewpoints and one overhead, as bench_segment.py does.
        ang = np.radians(np.arange(0, 360, 30))
        eyes = np.column_stack([1.5 * np.cos(ang), 1.5 * np.sin(ang), np.full(len(ang), 1.1)])
        eyes = np.vstack([eyes, [[0.0, 0.0, 2.0]]])
        pile = sample_scene(scene.vertices, scene.faces, scene.labels, 60000, viewpoints=eyes)
        depth = 9
    else:
        kwargs, depth = PILES[name]
        pile = make_pile(**kwargs)
        truth = {
            k + 1: (2 * float(np.sort(r.semi_axes)[1]), r.volume(), ellipsoid_area(r.semi_axes))
            for k, r in enumerate(pile.rocks)
        }
    v, f = poisson_mesh(pile.points, pile.normals, depth=depth)
    out = (pile.points, pile.labels, truth, v, f)
    path.write_bytes(pickle.dumps(out))
    return out


def score(name: str, points, labels, truth_rocks, v, f, params: SegmentParams) -> dict:
    t0 = time.perf_counter()
    seg = segment_mesh(v, f, params)
    seconds = time.perf_counter() - t0
    g = seg.geometry
    truth = truth_face_labels(g.centroids, points, labels)
    n = max(truth_rocks) + 1
    seen_area = np.bincount(truth, weights=g.areas, minlength=n)
    visible = [k for k, (_, _, area) in truth_rocks.items() if seen_area[k] >= 0.3 * area]
    _, _, rr, pp = rock_recall_precision(truth, seg.labels, g.areas)
    ids = np.unique(truth[truth > 0])
    keep = np.isin(ids, visible)
    rr, pp = rr[keep], pp[keep]
    rocks = measure_rocks(v, seg)
    b_err = []
    found = set()
    for rock in rocks:
        sel = seg.labels == rock.id
        w = np.bincount(truth[sel], weights=g.areas[sel], minlength=n)
        w[0] = 0
        k = int(np.argmax(w))
        if k in visible and w[k] >= 0.8 * w.sum() and w[k] >= 0.8 * seen_area[k]:
            found.add(k)
            b_err.append(rock.b / truth_rocks[k][0] - 1)
    true_b = [truth_rocks[k][0] for k in visible]
    true_m = [truth_rocks[k][1] * SPECIFIC_GRAVITY * 1000 for k in visible]
    d50_true = gradation(true_b, true_m).d50
    d50 = gradation([r.b for r in rocks], [r.mass for r in rocks]).d50
    a, b = v[f[:, 0]], v[f[:, 1]]
    return {
        'pile': name,
        'faces': len(f),
        'edge_mm': 1000 * float(np.median(np.linalg.norm(a - b, axis=1))),
        'visible': len(visible),
        'segments': int(seg.labels.max()),
        'measured': len(rocks),
        'recall': float(rr.mean()),
        'precision': float(pp.mean()),
        'found': len(found),
        'b_err': float(np.median(np.abs(b_err))) if b_err else float('nan'),
        'd50_err': (d50 / d50_true - 1) if d50 and d50_true else float('nan'),
        'seconds': seconds,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    names = [*PILES, 'demo']
    parser.add_argument('--piles', nargs='+', default=names, choices=names)
    parser.add_argument('--set', nargs='*', default=[], metavar='FIELD=VALUE')
    parser.add_argument('--cache', type=Path, default=Path('/tmp/stockpile_bench_scale'))
    args = parser.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    overrides = {k: ast.literal_eval(v) for k, v in (s.split('=', 1) for s in args.set)}
    params = SegmentParams.preset('default', **overrides)
    print(f'overrides: {overrides or "none"}')
    print('pile  faces    edge mm  visible segments measured recall precision found  '
          'b |err| D50 err  seconds')  # fmt: skip
    for name in args.piles:
        r = score(name, *load(name, args.cache), params)
        print(f'{r["pile"]:5s} {r["faces"]:8d} {r["edge_mm"]:6.2f}  {r["visible"]:7d} '
              f'{r["segments"]:8d} {r["measured"]:8d} {r["recall"]:6.3f} {r["precision"]:9.3f} '
              f'{r["found"]:5d}  {r["b_err"]:7.3f} {r["d50_err"]:+7.3f}  {r["seconds"]:6.2f}',
              flush=True)  # fmt: skip


if __name__ == '__main__':
    main()
