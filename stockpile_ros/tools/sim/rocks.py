"""Angular or rounded, irregular rock meshes and their exact geometric properties.

A rock is the convex hull of a few random points inside an ellipsoid, sampled radially from its
centroid by the vertices of a subdivided icosahedron (so the triangulation is even and the mesh is
closed and star-shaped), its edges and corners optionally worn round (the radius averaged over
nearby directions, as a river rounds a pebble), then roughened by a small radial displacement.
Star-shaped radial sampling can never fold the surface over itself, so volume and area from the
mesh are exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial import ConvexHull

from .noise import value_noise

__all__ = [
    'SHAPES',
    'RockMesh',
    'icosphere',
    'mesh_area',
    'mesh_volume',
    'principal_dimensions',
    'random_rock',
]

# Nominal a : b : c of each shape class (b = 1); the hull of random points then varies them.
SHAPES: dict[str, tuple[float, float, float]] = {
    'equant': (1.35, 1.0, 0.75),
    'flat': (1.4, 1.0, 0.38),
    'elongated': (2.3, 1.0, 0.7),
}


@dataclass
class RockMesh:
    """A closed, outward-oriented triangle mesh.

    Attributes:
        vertices: Nx3 float64 vertex positions [m].
        faces: Mx3 int64 vertex indices, counter-clockwise seen from outside.

    """

    vertices: npt.NDArray[np.float64]
    faces: npt.NDArray[np.int64]

    def transformed(
        self, rotation: npt.NDArray[np.float64], translation: npt.ArrayLike
    ) -> RockMesh:
        """Return a copy moved by ``x -> rotation @ x + translation``."""
        t = np.asarray(translation, dtype=np.float64)
        return RockMesh(self.vertices @ rotation.T + t, self.faces.copy())


def icosphere(subdivisions: int) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Return the unit icosphere (vertices on the unit sphere, outward faces).

    Args:
        subdivisions: Number of 1-to-4 midpoint subdivisions of the icosahedron.

    """
    g = (1 + 5**0.5) / 2
    v = np.array(
        [[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g],
         [0, -1, -g], [0, 1, -g], [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]],
        dtype=np.float64,
    )  # fmt: skip
    f = np.array(
        [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
         [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
         [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]],
        dtype=np.int64,
    )  # fmt: skip
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    for _ in range(subdivisions):
        edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        key = np.sort(edges, axis=1)
        uniq, inverse = np.unique(key, axis=0, return_inverse=True)
        mid = v[uniq[:, 0]] + v[uniq[:, 1]]
        mid /= np.linalg.norm(mid, axis=1, keepdims=True)
        m = inverse.reshape(3, -1) + len(v)
        a, b, c = f[:, 0], f[:, 1], f[:, 2]
        ab, bc, ca = m[0], m[1], m[2]
        f = np.concatenate(
            [np.stack(t, axis=1) for t in ((a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca))]
        )
        v = np.concatenate([v, mid])
    return v, f


def mesh_volume(mesh: RockMesh) -> float:
    """Volume of a closed, outward-oriented mesh (divergence theorem) [m^3]."""
    p = mesh.vertices[mesh.faces]
    return float(np.einsum('ij,ij->i', p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0)


def mesh_area(mesh: RockMesh) -> float:
    """Surface area [m^2]."""
    return float(triangle_areas(mesh).sum())


def triangle_areas(mesh: RockMesh) -> npt.NDArray[np.float64]:
    """Area of every face [m^2]."""
    p = mesh.vertices[mesh.faces]
    return np.asarray(0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1))


def solid_moments(
    mesh: RockMesh,
) -> tuple[float, npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Volume, centroid and central second moment (covariance x volume) of the enclosed solid.

    Sums signed tetrahedra (origin, face); for a tetrahedron with vertices p0..p3 the second moment
    is V/20 (sum p_i p_i^T + (sum p_i)(sum p_i)^T).
    """
    p = mesh.vertices[mesh.faces]
    vol = np.einsum('ij,ij->i', p[:, 0], np.cross(p[:, 1], p[:, 2])) / 6.0
    total = float(vol.sum())
    s = p.sum(axis=1)
    centroid = (vol[:, None] * s).sum(axis=0) / 4.0 / total
    outer = np.einsum('fki,fkj->fij', p, p) + np.einsum('fi,fj->fij', s, s)
    second = (vol[:, None, None] * outer).sum(axis=0) / 20.0
    central = second - total * np.outer(centroid, centroid)
    return total, centroid, central


def principal_dimensions(
    mesh: RockMesh,
) -> tuple[float, float, float, npt.NDArray[np.float64]]:
    """Extents a >= b >= c of the mesh along the principal axes of its solid (volume PCA).

    Returns:
        a, b, c [m] and the 3x3 matrix whose columns are the matching unit axes.

    """
    _, centroid, central = solid_moments(mesh)
    _, vecs = np.linalg.eigh(central)
    proj = (mesh.vertices - centroid) @ vecs
    ext = proj.max(axis=0) - proj.min(axis=0)
    order = np.argsort(ext)[::-1]
    a, b, c = (float(e) for e in ext[order])
    return a, b, c, np.asarray(vecs[:, order])


def _hull_radius(
    hull_points: npt.NDArray[np.float64], directions: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """Distance from the origin (inside the hull) to the hull surface along each unit direction."""
    eq = ConvexHull(hull_points).equations  # n . x + d <= 0 inside, |n| = 1
    cos = directions @ eq[:, :3].T
    with np.errstate(divide='ignore'):
        t = np.where(cos > 1e-12, -eq[:, 3] / cos, np.inf)
    return np.asarray(t.min(axis=1))


def _worn(
    dirs: npt.NDArray[np.float64], radius: npt.NDArray[np.float64], sigma: float
) -> npt.NDArray[np.float64]:
    """Average the radial function over directions within about ``sigma`` radians."""
    angle = np.arccos(np.clip(dirs @ dirs.T, -1.0, 1.0))
    weight = np.exp(-0.5 * (angle / sigma) ** 2)
    return np.asarray(weight @ radius / weight.sum(axis=1))


def random_rock(
    rng: np.random.Generator,
    b: float,
    shape: str = 'equant',
    roughness: float = 0.025,
    subdivisions: int = 4,
    rounding: float = 0.0,
) -> RockMesh:
    """Make one rock whose principal intermediate dimension is exactly ``b``.

    Args:
        rng: Random generator (the only source of randomness).
        b: Intermediate dimension [m] of the finished rock.
        shape: Key of :data:`SHAPES`.
        roughness: Amplitude of the radial surface roughness, as a fraction of the radius.
        subdivisions: Icosphere subdivisions (4: 5120 faces).
        rounding: How far the hull's edges and corners are worn round: the radius is averaged
            over directions with Gaussian weights of this standard deviation [radians; 0: the
            hull's sharp edges, angular quarry rock; 0.3 rounds every edge over about a third of
            the rock's half-width, as on river cobbles]. Draws nothing from ``rng``, so a bed with
            and without it has the same rocks in the same places but for their shape.

    Returns:
        The rock, centred on its centroid, long axis roughly along x and short axis along z.

    """
    if shape not in SHAPES:
        raise ValueError(f'unknown rock shape {shape!r}; use one of {sorted(SHAPES)}')
    ratios = np.asarray(SHAPES[shape]) * rng.uniform(0.85, 1.15, size=3)
    n_points = int(rng.integers(10, 28))
    pts = rng.normal(size=(n_points, 3))
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    pts *= rng.uniform(0.75, 1.0, size=(n_points, 1))
    # Six points on the axes keep the origin well inside and the extents near the nominal ratios.
    axes = np.concatenate([np.eye(3), -np.eye(3)]) * rng.uniform(0.85, 1.0, size=(6, 1))
    pts = np.concatenate([pts, axes]) * (ratios / 2)
    dirs, faces = icosphere(subdivisions)
    radius = _hull_radius(pts, dirs)
    if rounding > 0:
        radius = _worn(dirs, radius, rounding)
    freq = 4.0 / float(ratios.min())
    offset = rng.uniform(0, 1000, size=3)
    bumps = value_noise(dirs * ratios / 2 * freq + offset, octaves=3)
    radius = radius * (1.0 + roughness * (2.0 * bumps - 1.0))
    rock = RockMesh(dirs * radius[:, None], faces)
    _, centroid, _ = solid_moments(rock)
    rock.vertices -= centroid
    _, b_now, _, _ = principal_dimensions(rock)
    rock.vertices *= b / b_now
    return rock
