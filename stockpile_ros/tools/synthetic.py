"""Small synthetic piles of ellipsoidal rocks on the ground plane, for tests and benchmarks.

Every rock is an ellipsoid dropped onto the ground or onto the rocks already there; points are
sampled on the visible union surface (rock surfaces outside every other rock, ground outside every
rock) with exact normals, meshed with open3d's Poisson reconstruction, and each face gets the
label of
the nearest sample (its true rock, 0 for ground). This is the "perfect reconstruction" case: it
judges the segmentation alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

__all__ = [
    'Ellipsoid',
    'SyntheticPile',
    'make_pile',
    'poisson_mesh',
    'sample_scene',
    'seen_from',
    'truth_face_labels',
]

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Ellipsoid:
    """A rock: ``centre``, ``rotation`` (columns are the body axes in the world) and semi-axes."""

    centre: F64
    rotation: F64
    semi_axes: F64

    def inside(self, points: F64) -> npt.NDArray[np.bool_]:
        """Whether each point is strictly inside."""
        q = (points - self.centre) @ self.rotation / self.semi_axes
        inside: npt.NDArray[np.bool_] = np.einsum('ij,ij->i', q, q) < 1.0
        return inside

    def half_height(self) -> float:
        """Half of the vertical extent."""
        return float(np.sqrt(np.sum((self.rotation[2] * self.semi_axes) ** 2)))

    def surface(self, n: int, rng: np.random.Generator) -> tuple[F64, F64]:
        """Sample ``n`` surface points uniformly in area, with their unit normals."""
        out: list[F64] = []
        count = 0
        while count < n:
            u = rng.normal(size=(2 * n, 3))
            u /= np.linalg.norm(u, axis=1, keepdims=True)
            q = u * self.semi_axes
            grad = u / self.semi_axes
            weight = np.linalg.norm(grad, axis=1) * np.prod(self.semi_axes)
            keep = rng.random(len(u)) * weight.max() < weight
            out.append(q[keep])
            count += int(keep.sum())
        q = np.concatenate(out)[:n]
        g = q / self.semi_axes**2
        normals = g @ self.rotation.T
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        return q @ self.rotation.T + self.centre, normals

    def volume(self) -> float:
        """Volume."""
        return float(4.0 / 3.0 * np.pi * np.prod(self.semi_axes))


@dataclass(frozen=True)
class SyntheticPile:
    """Sampled visible surface of a pile.

    Attributes:
        rocks: The rocks; rock ``k`` has label ``k + 1``.
        points: Nx3 samples on the visible surface.
        normals: Nx3 outward unit normals.
        labels: N labels, 0 for ground.

    """

    rocks: list[Ellipsoid]
    points: F64
    normals: F64
    labels: npt.NDArray[np.int32]


def _random_rotation(rng: np.random.Generator) -> F64:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return np.asarray(q, dtype=np.float64)


def make_pile(
    n_rocks: int = 5,
    seed: int = 0,
    size: tuple[float, float] = (0.12, 0.3),
    spread: float = 0.35,
    density: float = 40000.0,
    max_overlap: float = 0.02,
    noise: float = 0.0,
    candidates: int = 6,
) -> SyntheticPile:
    """Drop ``n_rocks`` random ellipsoids onto the ground around the origin and sample the surface.

    Args:
        n_rocks: Number of rocks.
        seed: Random seed.
        size: Range of the longest semi-axis [m].
        spread: Radius of the disc the rocks fall into [m].
        density: Samples per square metre of surface.
        max_overlap: Depth a rock may sink into the ones below it [m]; creates the contact creases.
        noise: Standard deviation of Gaussian noise added to the points [m].
        candidates: Drop positions tried per rock; the lowest resting place wins.

    """
    rng = np.random.default_rng(seed)
    rocks: list[Ellipsoid] = []
    for _ in range(n_rocks):
        big = rng.uniform(*size)
        axes = big * np.array([1.0, rng.uniform(0.6, 0.9), rng.uniform(0.45, 0.7)])
        rot = _random_rotation(rng)
        shell = Ellipsoid(np.zeros(3), rot, axes - max_overlap)
        probe, _ = shell.surface(400, rng)
        rest = shell.half_height()
        top = max((r.centre[2] + r.half_height() for r in rocks), default=0.0)
        best: tuple[float, float, float] | None = None
        # A rock rolls into a low spot: of a few drop positions keep the one where it settles
        # lowest.
        for xy in rng.uniform(-1, 1, (candidates, 2)) * spread:
            z = rest
            for z_try in np.arange(top + rest + 0.01, rest - 1e-9, -0.005):
                pts = probe + np.array([xy[0], xy[1], z_try])
                if any(r.inside(pts).any() for r in rocks):
                    break
                z = float(z_try)
            if best is None or z < best[2]:
                best = (float(xy[0]), float(xy[1]), z)
        assert best is not None
        rocks.append(Ellipsoid(np.array(best), rot, axes))
    pts_all, nrm_all, lab_all = [], [], []
    for k, rock in enumerate(rocks):
        area = 4 * np.pi * (np.prod(rock.semi_axes) ** (2 / 3))
        p, n = rock.surface(int(area * density), rng)
        keep = p[:, 2] > 0
        for other, o in enumerate(rocks):
            if other != k:
                keep &= ~o.inside(p)
        pts_all.append(p[keep])
        nrm_all.append(n[keep])
        lab_all.append(np.full(int(keep.sum()), k + 1, dtype=np.int32))
    half = spread + size[1] * 1.5
    n_ground = int((2 * half) ** 2 * density)
    g = np.column_stack([rng.uniform(-half, half, (n_ground, 2)), np.zeros(n_ground)])
    keep = np.ones(n_ground, dtype=bool)
    for rock in rocks:
        keep &= ~rock.inside(g)
    pts_all.append(g[keep])
    nrm_all.append(np.tile([0.0, 0.0, 1.0], (int(keep.sum()), 1)))
    lab_all.append(np.zeros(int(keep.sum()), dtype=np.int32))
    points = np.concatenate(pts_all)
    if noise > 0:
        points = points + rng.normal(scale=noise, size=points.shape)
    return SyntheticPile(rocks, points, np.concatenate(nrm_all), np.concatenate(lab_all))


def poisson_mesh(
    points: F64,
    normals: F64,
    depth: int = 8,
    trim_quantile: float = 0.02,
    scale: float = 1.1,
    threads: int = -1,
) -> tuple[F64, npt.NDArray[np.int64]]:
    """Open3d screened Poisson surface of oriented points, trimmed.

    Low-density vertices are removed, and so is the closure the solver adds below the ground.

    Args:
        points: Nx3 points.
        normals: Nx3 unit normals.
        depth: Octree depth: the solver's cube is cut ``2^depth`` times.
        trim_quantile: Share of the lowest-density vertices removed.
        scale: The solver's cube over the points' bounding cube (open3d's default 1.1).
        threads: Solver threads (-1: all).

    Returns:
        Vertices and faces.

    """
    import open3d

    o3d: Any = open3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    pcd.normals = o3d.utility.Vector3dVector(normals)
    mesh, dens = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
        pcd, depth=depth, scale=scale, n_threads=threads
    )
    dens = np.asarray(dens)
    v = np.asarray(mesh.vertices)
    drop = (dens < np.quantile(dens, trim_quantile)) | (v[:, 2] < -0.01)
    mesh.remove_vertices_by_mask(drop)
    mesh.remove_unreferenced_vertices()
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.triangles, dtype=np.int64)


def truth_face_labels(
    centroids: F64, points: F64, labels: npt.NDArray[np.int32]
) -> npt.NDArray[np.int32]:
    """Label of the nearest sample to each face centroid."""
    _, idx = cKDTree(points).query(centroids)
    return np.asarray(labels[idx], dtype=np.int32)


def sample_scene(
    vertices: F64,
    faces: npt.NDArray[np.int64],
    labels: npt.NDArray[np.int32],
    density: float = 50000.0,
    margin: float = 0.2,
    seed: int = 0,
    viewpoints: F64 | None = None,
) -> SyntheticPile:
    """Sample the visible union surface of a labelled scene mesh (the simulator's ``scene.ply``).

    Each closed rock mesh (label > 0) is sampled uniformly in area and the samples inside any other
    rock or under the ground are dropped; the ground (label 0) is sampled on ``z = 0`` over the
    rocks' bounding box grown by ``margin``, outside every rock. Normals are the sampled faces'.
    With ``viewpoints`` (Kx3 camera positions), only samples
    with a clear line of sight to at least one of them are kept, as a camera survey would see.

    Returns:
        Samples with labels; ``rocks`` is empty (the truth is in the simulator's truth.json).

    """
    import open3d

    o3d: Any = open3d

    rng = np.random.default_rng(seed)
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    ids = [int(k) for k in np.unique(labels) if k > 0]
    scenes = []
    for k in ids:
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(
            o3d.core.Tensor(v.astype(np.float32)), o3d.core.Tensor(f[labels == k].astype(np.uint32))
        )
        scenes.append(scene)

    def inside_any(points: F64, skip: int | None) -> npt.NDArray[np.bool_]:
        hit = np.zeros(len(points), dtype=bool)
        query = o3d.core.Tensor(points.astype(np.float32))
        for k, scene in zip(ids, scenes, strict=True):
            if k != skip:
                hit |= scene.compute_occupancy(query).numpy() > 0.5
        return hit

    pts_all, nrm_all, lab_all = [], [], []
    for k in ids:
        tri = v[f[labels == k]]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area = 0.5 * np.linalg.norm(cross, axis=1)
        n = int(area.sum() * density)
        pick = rng.choice(len(tri), size=n, p=area / area.sum())
        r1, r2 = rng.random(n), rng.random(n)
        flip = r1 + r2 > 1
        r1[flip], r2[flip] = 1 - r1[flip], 1 - r2[flip]
        t = tri[pick]
        p = t[:, 0] + r1[:, None] * (t[:, 1] - t[:, 0]) + r2[:, None] * (t[:, 2] - t[:, 0])
        nrm = cross[pick] / np.linalg.norm(cross[pick], axis=1, keepdims=True)
        keep = (p[:, 2] > 0) & ~inside_any(p, k)
        pts_all.append(p[keep])
        nrm_all.append(nrm[keep])
        lab_all.append(np.full(int(keep.sum()), k, dtype=np.int32))
    rock_v = v[np.unique(f[labels > 0])]
    lo, hi = rock_v[:, :2].min(axis=0) - margin, rock_v[:, :2].max(axis=0) + margin
    n_ground = int(np.prod(hi - lo) * density)
    g = np.column_stack([rng.uniform(lo, hi, (n_ground, 2)), np.zeros(n_ground)])
    keep = ~inside_any(g + np.array([0.0, 0.0, 1e-4]), None)
    pts_all.append(g[keep])
    nrm_all.append(np.tile([0.0, 0.0, 1.0], (int(keep.sum()), 1)))
    lab_all.append(np.zeros(int(keep.sum()), dtype=np.int32))
    points, normals = np.concatenate(pts_all), np.concatenate(nrm_all)
    point_labels = np.concatenate(lab_all)
    if viewpoints is not None:
        seen = seen_from(v, f[labels > 0], points, normals, viewpoints).any(axis=1)
        points, normals, point_labels = points[seen], normals[seen], point_labels[seen]
    return SyntheticPile([], points, normals, point_labels)


def seen_from(
    vertices: F64, faces: npt.NDArray[np.int64], points: F64, normals: F64, viewpoints: F64
) -> npt.NDArray[np.bool_]:
    """Whether each point (row) is seen from each viewpoint (column).

    A point is seen from a viewpoint on the outer side of its surface (along its unit normal)
    when no triangle of ``vertices`` and ``faces`` (what can hide it: the rocks) lies between.
    """
    import open3d

    o3d: Any = open3d

    hiding = o3d.t.geometry.RaycastingScene()
    hiding.add_triangles(
        o3d.core.Tensor(np.asarray(vertices).astype(np.float32)),
        o3d.core.Tensor(np.asarray(faces).astype(np.uint32)),
    )
    eyes = np.asarray(viewpoints, dtype=np.float64)
    seen = np.zeros((len(points), len(eyes)), dtype=bool)
    start = points + normals * 1e-4
    for k, eye in enumerate(eyes):
        ray = eye - start
        dist = np.linalg.norm(ray, axis=1)
        rays = np.hstack([start, ray / dist[:, None]]).astype(np.float32)
        hit = hiding.cast_rays(o3d.core.Tensor(rays))['t_hit'].numpy()
        seen[:, k] = (hit >= dist) & (np.einsum('ij,ij->i', ray, normals) > 0)
    return seen
