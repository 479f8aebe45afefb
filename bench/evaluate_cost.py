"""Print the cost of `stockpile evaluate`'s label transfer and matching against result mesh size.

Usage: .venv/bin/python bench/evaluate_cost.py TRUTH_DIR [--faces N ...]

The truth scene itself, split into more faces (each triangle into 4 per level), stands in for a
result mesh of that size; it is matched against the truth scene.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from stockpile_ros.meshio import LabelledMesh
from stockpile_ros.tools.evaluation.inputs import load_truth
from stockpile_ros.tools.evaluation.match import MatchOptions, match_rocks, transfer_labels


def subdivide(mesh: LabelledMesh) -> LabelledMesh:
    """Split every triangle into 4 at its edge midpoints (shared vertices duplicated)."""
    tri = mesh.vertices[mesh.faces]
    mid = (tri + np.roll(tri, -1, axis=1)) / 2
    n = len(mesh.faces)
    verts = np.concatenate([tri.reshape(-1, 3), mid.reshape(-1, 3)])
    c = np.arange(3 * n).reshape(n, 3)
    m = 3 * n + c
    faces = np.concatenate(
        [
            np.stack([c[:, 0], m[:, 0], m[:, 2]], 1),
            np.stack([c[:, 1], m[:, 1], m[:, 0]], 1),
            np.stack([c[:, 2], m[:, 2], m[:, 1]], 1),
            m,
        ]
    )
    return LabelledMesh(verts, faces, np.tile(mesh.labels, 4))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('truth')
    parser.add_argument('--faces', type=int, nargs='+', default=[100_000, 400_000, 1_600_000])
    args = parser.parse_args()
    truth = load_truth(args.truth)
    print(f'truth scene: {len(truth.scene.faces)} faces')
    ids = sorted(truth.rocks)
    for target in args.faces:
        mesh = truth.scene
        while len(mesh.faces) < target:
            mesh = subdivide(mesh)
        start = time.perf_counter()
        transfer = transfer_labels(mesh.vertices, mesh.faces, truth.scene, 0.02)
        mid = time.perf_counter()
        matching = match_rocks(mesh.labels[transfer.face], transfer, ids, ids, MatchOptions())
        end = time.perf_counter()
        print(
            f'result {len(mesh.faces):>9} faces: label transfer {mid - start:6.2f} s, '
            f'matching {end - mid:5.2f} s, {len(matching.pairs)}/{len(ids)} rocks matched'
        )


if __name__ == '__main__':
    main()
