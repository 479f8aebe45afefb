"""Shared by the segmentation tests: a small synthetic pile, height fields, a made-up report."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import numpy.typing as npt

from stockpile_ros.artefacts import KeyframePose, ScaleRecord
from stockpile_ros.meshio import LabelledMesh, write_labelled_mesh
from stockpile_ros.result import MeasureRecord, MeshRecord, Report, RockRecord, SegmentationRecord
from stockpile_ros.segment.params import RockScale
from stockpile_ros.segment.pipeline import grade
from stockpile_ros.segment.qa import ReportOptions
from stockpile_ros.tools.synthetic import make_pile, poisson_mesh


@functools.lru_cache(maxsize=1)
def small_pile() -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], object]:
    pile = make_pile(4, seed=3, size=(0.15, 0.22), spread=0.2, density=20000, candidates=3)
    v, f = poisson_mesh(pile.points, pile.normals, depth=7)
    return v, f, pile


def small_pile_file(folder: Path) -> Path:
    """Write the small pile's mesh (no labels) as ``folder/mesh.ply``; return its path."""
    v, f, _ = small_pile()
    path = folder / 'mesh.ply'
    write_labelled_mesh(path, LabelledMesh(v, f, np.zeros(len(f), dtype=np.int32)))
    return path


def height_field(
    z: Callable[[npt.NDArray[np.float64], npt.NDArray[np.float64]], npt.NDArray[np.float64]],
    half: float,
    n: int,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Triangulated ``z(x, y)`` on an ``n`` x ``n`` grid over ``[-half, half]^2``, normals up."""
    x, y = np.meshgrid(np.linspace(-half, half, n), np.linspace(-half, half, n), indexing='ij')
    v = np.stack([x.ravel(), y.ravel(), z(x, y).ravel()], axis=1)
    k = np.arange(n * n).reshape(n, n)
    a, b, c, d = k[:-1, :-1].ravel(), k[1:, :-1].ravel(), k[1:, 1:].ravel(), k[:-1, 1:].ravel()
    f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return v, f


def boulders_on(
    ground: Callable[[npt.NDArray[np.float64], npt.NDArray[np.float64]], npt.NDArray[np.float64]],
    centres: list[tuple[float, float]],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Half ellipsoids of radius 0.2 m and 0.14 m high standing on ``ground`` at ``centres``,
    meshed every 7 mm over 2.8 m."""

    def surface(x: npt.NDArray[np.float64], y: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        z = ground(x, y)
        for cx, cy in centres:
            cap = float(ground(np.array(cx), np.array(cy))) + 0.7 * np.sqrt(
                np.clip(0.2**2 - (x - cx) ** 2 - (y - cy) ** 2, 0, None)
            )
            z = np.where((x - cx) ** 2 + (y - cy) ** 2 < 0.2**2, np.maximum(z, cap), z)
        return z

    return height_field(surface, 1.4, 200)


def make_report(
    rocks: list[RockRecord],
    scale: ScaleRecord,
    keyframes: list[KeyframePose] | None = None,
    frame_id: str = 'stockpile',
    d50: float | None = None,
) -> Report:
    """A report of the given rocks, as a result folder's ``report.json`` holds one.

    Its gradation is that of no rock but for ``d50``, and its segmentation and mesh records hold
    fixed small values: the tests it feeds (evaluation, capture warnings) read rocks, scale and
    warnings.
    """
    gradation = grade(
        [], None, scale.rel_uncertainty, ReportOptions(resamples=100), scale.metric, resolved_b=0.0
    )
    segmentation = SegmentationRecord(
        scale=RockScale(0.005, 0.1, 'mesh', 0.1, 0.0075, 0.015),
        raw_regions=len(rocks),
        segments=len(rocks),
        rocks_measured=len(rocks),
        seconds=0.0,
        measure=MeasureRecord(),
    )
    return Report(
        frame_id=frame_id,
        units='m' if scale.metric else 'model',
        scale=scale,
        keyframes=keyframes or [],
        rocks=rocks,
        gradation=replace(gradation, d50=d50),
        segmentation=segmentation,
        mesh=MeshRecord(faces=0, vertices=0, source='made up'),
    )
