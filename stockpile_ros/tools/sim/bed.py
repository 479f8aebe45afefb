"""A bed of hundreds of rocks that covers the ground, and its top surface meshed at a chosen scale.

The yardstick the segmentation is judged on at field scale: a survey looks down on a bed or a
pile face where rocks touch rocks and no ground shows between them, with hundreds of rocks of a
size range set by the material (aggregate a few centimetres, riprap up to a metre and a half)
and a mesh whose resolution is set by how close the camera was. What matters to the
segmentation is the rocks' shapes, how they touch, and how many mesh edges lie across a rock;
the absolute size only scales everything, so each material class is a gradation, and the mesh
resolution is given in edges across the smallest rock's b.

Rocks (the simulator's angular rock meshes, with flat and elongated shares, or the same worn round
as a river's) are dropped one at a
time at random points over a square, each onto the heightfield of the ground and the rocks
already there (see :mod:`.pile`); of a few drop points the lowest resting place wins (rocks settle
into hollows), and each rock then sinks a random share of its height into what lies under it
(bedded and partly buried rocks). The square's area is the rocks' summed plan area over ``cover``,
so the bed is more than one layer thick and nothing of the ground shows inside it.

The surface is what a survey from above reconstructs: points where rays from straight above and
from four oblique directions first hit a rock or the ground, displaced along their normals by a
smooth relief correlated over a few cells (dense matching's errors are, and Poisson does not
average them away) and by white noise of a share of the cell, meshed by screened Poisson at a
chosen finest cell (it rounds the creases between rocks over a few cells and bridges what no ray
saw, as on a reconstructed pile); each face takes the label of the nearest point.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt
import open3d as o3d
from scipy.ndimage import gaussian_filter, map_coordinates
from scipy.spatial import cKDTree

from ...cloud.mesh import estimate_normals
from ...errors import StockpileError
from ..synthetic import poisson_mesh
from .pile import (
    Gradation,
    PileConfig,
    PlacedRock,
    _Heightfield,
    _resting_rotation,
    _shapes,
    _under_and_over,
    parse_gradation,
)
from .rocks import SHAPES, random_rock, triangle_areas
from .truth import rock_truth

__all__ = ['MATERIALS', 'BedConfig', 'BedSurface', 'bed_surface', 'build_bed', 'drape']

F64 = npt.NDArray[np.float64]

#: Range of b [m] of each material class the yardstick covers (mass spread evenly in log size).
MATERIALS: dict[str, tuple[float, float]] = {
    'aggregate': (0.02, 0.08),
    'cobble': (0.1, 0.3),
    'riprap': (0.3, 1.5),
}


@dataclass(frozen=True)
class BedConfig:
    """Parameters of a bed.

    Attributes:
        rocks: Number of rocks.
        gradation: Size distribution of b [m].
        flat_fraction: Share of flat rocks (c about 0.38 b).
        elongated_fraction: Share of elongated rocks (a about 2.3 b).
        roughness: Radial roughness amplitude (share of the radius).
        rounding: How far the rocks' edges are worn round (``random_rock``) [radians; 0: angular
            quarry rock, 0.3: river cobbles].
        subdivisions: Icosphere subdivisions per rock (3: 1280 faces).
        cover: Summed plan area of the rocks over the area of the square they fall on (above 1:
            more than one layer; on beds of 110 rocks of 0.1-0.3 m the ground showed on 10 % of
            the middle of the bed at 2.5, 8 % at 3 and 0.2 % at 4).
        cell_b: Cell of the settling heightfield [in units of the smallest b drawn].
        candidates: Drop points tried per rock; the lowest resting place wins.
        sink: Largest share of its own height a rock sinks into what lies under it (drawn
            evenly from 0 to this).

    """

    rocks: int = 300
    gradation: Gradation = field(default_factory=lambda: parse_gradation('0.3:1.5'))
    flat_fraction: float = 0.2
    elongated_fraction: float = 0.2
    roughness: float = 0.025
    rounding: float = 0.0
    subdivisions: int = 3
    cover: float = 4.0
    cell_b: float = 0.08
    candidates: int = 12
    sink: float = 0.3


def build_bed(rng: np.random.Generator, cfg: BedConfig) -> list[PlacedRock]:
    """Drop ``cfg.rocks`` rocks over a square centred on the origin until they cover it.

    Raises:
        StockpileError: The configuration has no rock or no cover.

    """
    if cfg.rocks < 1 or cfg.cover <= 0:
        raise StockpileError('a bed needs at least one rock and a positive cover')
    sizes = cfg.gradation.sample(rng, cfg.rocks)
    shape_cfg = PileConfig(
        rocks=cfg.rocks,
        flat_fraction=cfg.flat_fraction,
        elongated_fraction=cfg.elongated_fraction,
    )
    shapes = _shapes(rng, shape_cfg)
    plan = sum(np.pi / 4 * SHAPES[s][0] * float(b) ** 2 for b, s in zip(sizes, shapes, strict=True))
    half = 0.5 * float(np.sqrt(plan / cfg.cover))
    cell = cfg.cell_b * float(sizes.min())
    field_ = _Heightfield(half + 2.0 * float(sizes.max()), cell)
    placed: list[PlacedRock] = []
    for k, (b, shape) in enumerate(zip(sizes, shapes, strict=True)):
        rock = random_rock(rng, float(b), shape, cfg.roughness, cfg.subdivisions, cfg.rounding)
        mesh = rock.transformed(_resting_rotation(rng), np.zeros(3))
        bottom, top, idx = _under_and_over(mesh, cell)
        best: tuple[float, npt.NDArray[np.int64]] | None = None
        for xy in rng.uniform(-half, half, size=(cfg.candidates, 2)):
            shift = np.round(xy / cell).astype(np.int64)
            dz = field_.rest_height(bottom, idx + shift)
            if best is None or dz < best[0]:
                best = (dz, shift)
        assert best is not None
        dz, shift = best
        dz -= rng.uniform(0.0, cfg.sink) * float(top.max() - bottom.min())
        field_.add(top + dz, idx + shift)
        moved = mesh.transformed(np.eye(3), [shift[0] * cell, shift[1] * cell, dz])
        placed.append(PlacedRock(id=k + 1, shape=shape, b_nominal=float(b), mesh=moved))
    return placed


@dataclass(frozen=True)
class BedSurface:
    """The surface of a bed as a survey reconstructs it, with the true rock under every face.

    Attributes:
        vertices: Nx3 vertex positions [m], z up, ground at ``z = 0``.
        faces: Mx3 triangles, normals outward.
        labels: Per face, the id of the true surface nearest its centroid (0: ground).
        rocks: Truth record of every rock by id (keys of ``truth.json``: ``b``, ``volume``,
            ``mass``, ``area``, ``visible_fraction``: the share of the rock's surface area that
            a ray of the survey hit, ...).
        cell: Finest Poisson cell [m].

    """

    vertices: F64
    faces: npt.NDArray[np.int64]
    labels: npt.NDArray[np.int32]
    rocks: dict[int, dict[str, Any]]
    cell: float


#: Directions the survey looks from: straight down and tilted by ``TILT`` rad in four azimuths,
#: so that the steep flanks of rocks are seen as a camera cart passing by sees them.
TILT = 0.5
#: Finest Poisson cell over the survey's ray spacing: one ray per cell and direction.
RAYS_PER_CELL = 1.0
#: Rays across the smallest rock's b of the survey that finds which rock triangles were seen
#: (the truth's visible fractions): the rocks' triangles are about b / 16 across.
VISIBILITY_RAYS_PER_B = 32.0


def _directions() -> F64:
    az = np.arange(4) * np.pi / 2
    tilted = np.column_stack(
        [np.sin(TILT) * np.cos(az), np.sin(TILT) * np.sin(az), -np.full(4, np.cos(TILT))]
    )
    return np.vstack([[0.0, 0.0, -1.0], tilted])


def _survey(
    scene: Any, lo: F64, hi: F64, z_top: float, step: float, rng: np.random.Generator
) -> Iterator[tuple[F64, npt.NDArray[np.int64], npt.NDArray[np.int64], F64]]:
    """Per direction, the first hits of parallel rays ``step`` apart over ``lo``..``hi`` in xy.

    Yields:
        Hit points, geometry and triangle ids, and the hit triangles' normals.

    """
    nx, ny = (int(np.ceil(s / step)) + 1 for s in hi - lo)
    gx, gy = np.meshgrid(lo[0] + step * np.arange(nx), lo[1] + step * np.arange(ny), indexing='ij')
    grid = np.stack([gx.ravel(), gy.ravel()], axis=1)
    for d in _directions():
        xy = grid + rng.uniform(-0.5, 0.5, size=grid.shape) * step
        # Start on the plane above the bed, shifted back along the ray so that it lands on xy.
        origin = np.column_stack([xy, np.full(len(xy), z_top)]) - d * (z_top / -d[2])
        rays = np.hstack([origin, np.tile(d, (len(xy), 1))]).astype(np.float32)
        hit = scene.cast_rays(o3d.core.Tensor.from_numpy(rays), nthreads=1)
        t = hit['t_hit'].numpy().astype(np.float64)
        ok = np.isfinite(t)
        yield (
            origin[ok] + t[ok, None] * d,
            hit['geometry_ids'].numpy().astype(np.int64)[ok],
            hit['primitive_ids'].numpy().astype(np.int64)[ok],
            hit['primitive_normals'].numpy().astype(np.float64)[ok],
        )


def _relief_field(points: F64, length: float, rng: np.random.Generator) -> tuple[F64, F64]:
    """Return a smooth random field of unit standard deviation at ``points``, and its gradient.

    White noise on a lattice of ``length / 2``, blurred by one lattice step (so its correlation
    length is about ``length``), normalised, and read off trilinearly; the gradient by central
    differences a quarter of ``length`` apart.
    """
    step = length / 2.0
    origin = points.min(axis=0) - 2.0 * step
    shape = tuple(int(n) for n in np.ceil((points.max(axis=0) + 2.0 * step - origin) / step) + 1)
    grid = gaussian_filter(rng.standard_normal(shape, dtype=np.float32), 1.0, mode='wrap')
    grid /= grid.std()

    def at(q: F64) -> F64:
        read: F64 = map_coordinates(grid, ((q - origin) / step).T, order=1, mode='nearest')
        return read.astype(np.float64)

    h = length / 4.0
    gradient = np.column_stack(
        [(at(points + h * e) - at(points - h * e)) / (2.0 * h) for e in np.eye(3)]
    )
    return at(points), gradient


def bed_surface(
    rocks: list[PlacedRock],
    cell: float,
    rng: np.random.Generator,
    noise_cells: float = 0.0,
    trim_quantile: float = 0.02,
    relief_cells: float = 0.0,
    relief_length_cells: float = 3.0,
    normal_neighbours: int = 0,
) -> BedSurface:
    """Survey ``rocks`` (and the ground round them) from above and mesh what was seen by Poisson.

    Parallel rays from five directions (see ``_directions``), ``RAYS_PER_CELL`` per ``cell``
    across, hit the rocks and the ground; the hits, with their triangles' normals and noise along
    them, are meshed by screened Poisson with its finest cell ``cell`` (the octree depth and the
    cube's scale chosen so), low-density vertices trimmed, and each face takes the label of the
    nearest hit. A rock triangle counts as seen when a ray of a finer survey of the same
    directions, ``VISIBILITY_RAYS_PER_B`` rays across the smallest rock, hits it.

    Args:
        rocks: The rocks of a bed or pile.
        cell: Finest Poisson cell [m] (about the median edge of the mesh).
        rng: Random generator (ray jitter and noise).
        noise_cells: Standard deviation of the noise of the points along their normals, each
            point's its own [in ``cell``].
        trim_quantile: Share of the lowest-density Poisson vertices removed.
        relief_cells: Standard deviation of a smooth random displacement of the points along
            their normals, their normals tilted with it, as dense matching's errors are
            correlated over a few cells [in ``cell``; 0: none]. White noise alone is averaged
            away by Poisson and leaves a cleaner surface than a reconstructed pile's.
        relief_length_cells: Correlation length of that displacement [in ``cell``].
        normal_neighbours: Poisson's normals are the true ones (0) or, as a survey or dense
            matching has to, estimated by a plane fit to this many nearest of the noisy points
            and turned towards the ray that found each point [points]. They make the bed
            harder to segment: the cobble bed at 30 edges with 0.2 cells of noise read
            0.93/0.95 in recall/precision with true normals, 0.87/0.90 with 20 points.

    Raises:
        StockpileError: The cell is not positive or there is no rock.

    """
    if cell <= 0 or not rocks:
        raise StockpileError('a bed surface needs rocks and a positive cell')
    scene = o3d.t.geometry.RaycastingScene()
    labels_of = []
    for rock in rocks:
        scene.add_triangles(
            o3d.core.Tensor.from_numpy(np.ascontiguousarray(rock.mesh.vertices, np.float32)),
            o3d.core.Tensor.from_numpy(np.ascontiguousarray(rock.mesh.faces, np.uint32)),
        )
        labels_of.append(rock.id)
    allv = np.concatenate([r.mesh.vertices for r in rocks])
    # The survey's extent and rays must not depend on the cell where the truth is taken from it.
    smallest = min(r.b_nominal for r in rocks)
    lo, hi = allv[:, :2].min(axis=0) - smallest, allv[:, :2].max(axis=0) + smallest
    side = float(np.max(hi - lo))
    ground = np.array(
        [[lo[0] - side, lo[1] - side, 0.0], [hi[0] + side, lo[1] - side, 0.0],
         [hi[0] + side, hi[1] + side, 0.0], [lo[0] - side, hi[1] + side, 0.0]],
        dtype=np.float32,
    )  # fmt: skip
    scene.add_triangles(
        o3d.core.Tensor.from_numpy(ground),
        o3d.core.Tensor.from_numpy(np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32)),
    )
    labels_of.append(0)
    to_label = np.array(labels_of, dtype=np.int32)
    z_top = float(allv[:, 2].max()) + smallest
    # Rock k's triangles are numbered from first[k] on in one array over every rock.
    first = np.concatenate([[0], np.cumsum([len(r.mesh.faces) for r in rocks])])
    seen = np.zeros(int(first[-1]), dtype=bool)
    # What was seen is surveyed at a spacing of the smallest rock, however coarse the cell.
    fine = smallest / VISIBILITY_RAYS_PER_B
    points, normals, labels, rays = [], [], [], []
    for _, gid, prim, _ in _survey(scene, lo, hi, z_top, fine, rng):
        on_rock = gid < len(rocks)
        seen[first[gid[on_rock]] + prim[on_rock]] = True
    for d, (hit, gid, _, nrm) in zip(
        _directions(), _survey(scene, lo, hi, z_top, cell / RAYS_PER_CELL, rng), strict=True
    ):
        points.append(hit)
        normals.append(nrm)
        labels.append(to_label[gid])
        rays.append(np.tile(d, (len(hit), 1)))
    p, n = np.concatenate(points), np.concatenate(normals)
    point_labels = np.concatenate(labels)
    if relief_cells > 0:
        value, gradient = _relief_field(p, relief_length_cells * cell, rng)
        sigma = relief_cells * cell
        p = p + n * (sigma * value)[:, None]
        # The displaced surface's normal: the field's gradient along the surface tilts it.
        along = gradient - np.sum(gradient * n, axis=1, keepdims=True) * n
        n = n - sigma * along
        n /= np.linalg.norm(n, axis=1, keepdims=True)
    if noise_cells > 0:
        p = p + n * rng.normal(0.0, noise_cells * cell, size=(len(p), 1))
    if normal_neighbours > 0:
        # The cloud route's own estimate, each sensor a step back along its ray.
        n, _ = estimate_normals(p, p - np.concatenate(rays), normal_neighbours, cell)
    extent = float(np.max(p.max(axis=0) - p.min(axis=0)))
    # The solver's cube is ``scale`` times the points' bounding cube, cut 2^depth times.
    depth = max(1, int(np.ceil(np.log2(1.1 * extent / cell))))
    vertices, faces = poisson_mesh(p, n, depth, trim_quantile, cell * 2**depth / extent, 1)
    centres = vertices[faces].mean(axis=1)
    _, nearest = cKDTree(p).query(centres)
    truth = {}
    for k, rock in enumerate(rocks):
        areas = triangle_areas(rock.mesh)
        hit_faces = seen[first[k] : first[k + 1]]
        truth[rock.id] = rock_truth(rock, float(areas[hit_faces].sum() / areas.sum()))
    return BedSurface(vertices, faces, point_labels[nearest].astype(np.int32), truth, cell)


def drape(surface: BedSurface, amplitude: float, length: float) -> BedSurface:
    """Lay the bed over uneven ground: raise every vertex by a wave of its plan position.

    ``z += amplitude sin(2 pi x / length) cos(2 pi y / length)``: ``z = 0`` is the site's mean
    plane, as a plane fitted through its ground would be, with hollows ``amplitude`` under it and
    crests as far over it. A vertical shear rather than a bed dropped on the wave: the rocks lean
    with the ground and stretch along it by ``sqrt(1 + slope^2)`` (about 2 % at a slope of 0.2),
    which the truth does not follow.

    Args:
        surface: The bed's surface on flat ground.
        amplitude: Half the ground's rise from hollow to crest [m].
        length: Wavelength along x and along y [m].

    Raises:
        StockpileError: The wavelength is not positive.

    """
    if length <= 0:
        raise StockpileError('a wave needs a positive length')
    v = surface.vertices.copy()
    k = 2.0 * np.pi / length
    v[:, 2] += amplitude * np.sin(k * v[:, 0]) * np.cos(k * v[:, 1])
    return replace(surface, vertices=v)
