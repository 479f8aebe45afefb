"""Ground truth of a simulated pile: per-rock geometry, visibility, gradation, the truth folder.

Everything here is computed from the exact meshes and from what the recorded views actually hit,
in the layout of ``docs/formats.md`` (``<BAG>_truth/truth.json`` and ``scene.ply``). The gradation
arithmetic is the shared one of :mod:`stockpile_ros.segment.gradation`, so that truth and results
are summarised alike.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ...meshio import LabelledMesh, write_labelled_mesh
from .pile import PlacedRock
from .rocks import mesh_area, principal_dimensions, solid_moments, triangle_areas

__all__ = [
    'DIMENSION_METHOD',
    'SPECIFIC_GRAVITY',
    'TRUTH_SCHEMA',
    'VisibilityAccumulator',
    'rock_truth',
    'scene_mesh',
    'write_truth',
]

TRUTH_SCHEMA = 'stockpile-truth/1'
SPECIFIC_GRAVITY = 2.65
WATER_DENSITY = 1000.0
DIMENSION_METHOD = (
    'extents of the closed rock mesh along the principal axes of its solid (volume PCA), '
    'sorted a >= b >= c'
)


class VisibilityAccumulator:
    """Marks the rock triangles that at least one recorded view hit.

    Args:
        rocks: The rocks in the order the renderer concatenated them.

    """

    def __init__(self, rocks: Sequence[PlacedRock]):
        self.labels = np.concatenate(
            [np.full(len(r.mesh.faces), r.id, dtype=np.int32) for r in rocks]
        )
        self.areas = np.concatenate([triangle_areas(r.mesh) for r in rocks])
        self.seen = np.zeros(len(self.labels), dtype=bool)

    def add(self, triangles: npt.NDArray[np.int64]) -> None:
        """Mark triangles (indices into the concatenated rock faces) as seen."""
        self.seen[triangles] = True

    def fractions(self) -> dict[int, float]:
        """Seen share of each rock's surface area, by rock id."""
        ids = np.unique(self.labels)
        total = np.bincount(self.labels, weights=self.areas)
        seen = np.bincount(self.labels, weights=self.areas * self.seen, minlength=len(total))
        return {int(i): float(seen[i] / total[i]) for i in ids}


def rock_truth(rock: PlacedRock, visible_fraction: float) -> dict[str, Any]:
    """Return the truth record of one rock (keys of ``docs/formats.md``)."""
    volume, centroid, _ = solid_moments(rock.mesh)
    a, b, c, _ = principal_dimensions(rock.mesh)
    return {
        'id': rock.id,
        'centroid': [float(v) for v in centroid],
        'a': a,
        'b': b,
        'c': c,
        'esd': float((6.0 * volume / math.pi) ** (1.0 / 3.0)),
        'volume': volume,
        'mass': volume * SPECIFIC_GRAVITY * WATER_DENSITY,
        'area': mesh_area(rock.mesh),
        'visible_fraction': visible_fraction,
        'shape_class': rock.shape,
        'fer': a / c,
    }


def scene_mesh(
    rocks: Sequence[PlacedRock], ground_half: float, ground_cells: int = 8
) -> LabelledMesh:
    """Return the labelled scene: a ground grid (label 0) and each rock's closed mesh (its id)."""
    g = np.linspace(-ground_half, ground_half, ground_cells + 1)
    gx, gy = np.meshgrid(g, g, indexing='ij')
    verts = [np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])]
    i = np.arange(ground_cells)[:, None] * (ground_cells + 1) + np.arange(ground_cells)[None, :]
    i = i.ravel()
    n1 = ground_cells + 1
    faces = [
        np.concatenate([np.stack([i, i + n1, i + n1 + 1], 1), np.stack([i, i + n1 + 1, i + 1], 1)])
    ]
    labels = [np.zeros(len(faces[0]), dtype=np.int32)]
    offset = len(verts[0])
    for rock in rocks:
        verts.append(rock.mesh.vertices)
        faces.append(rock.mesh.faces + offset)
        labels.append(np.full(len(rock.mesh.faces), rock.id, dtype=np.int32))
        offset += len(rock.mesh.vertices)
    return LabelledMesh(
        vertices=np.concatenate(verts),
        faces=np.concatenate(faces).astype(np.int64),
        labels=np.concatenate(labels),
    )


def write_truth(folder: str | Path, truth: dict[str, Any], mesh: LabelledMesh) -> None:
    """Write ``truth.json`` and ``scene.ply`` into ``folder`` (created if needed)."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    (out / 'truth.json').write_text(json.dumps(truth, indent=1, allow_nan=False) + '\n')
    write_labelled_mesh(out / 'scene.ply', mesh)
