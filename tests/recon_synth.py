"""Small synthetic scenes for the reconstruction tests: textured ground, rocks, ray-cast views."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import open3d as o3d
from scipy.ndimage import map_coordinates

F64 = npt.NDArray[np.float64]


def texture(points: F64, seed: int = 0) -> npt.NDArray[np.uint8]:
    """Colour of 3D points from multi-octave value noise (rich, repeatable texture for SIFT)."""
    rng = np.random.default_rng(seed)
    out = np.zeros((len(points), 3))
    for octave, cell in enumerate((0.2, 0.07, 0.025, 0.01)):
        lattice = rng.random((3, 64, 64, 64))
        coords = (points / cell).T % 63
        for c in range(3):
            out[:, c] += map_coordinates(lattice[c], coords, order=1, mode='wrap') / (octave + 1)
    out -= out.min(axis=0)
    out /= out.max(axis=0) + 1e-9
    return (out * 255).astype(np.uint8)


def scene_mesh(seed: int = 0, rocks: int = 6) -> o3d.geometry.TriangleMesh:
    """A 4 m x 4 m ground with a few ellipsoidal rocks of 0.2-0.5 m near the origin."""
    rng = np.random.default_rng(seed)
    ground = o3d.geometry.TriangleMesh.create_box(4.0, 4.0, 0.01)
    ground.translate((-2.0, -2.0, -0.01))
    mesh = ground
    for _ in range(rocks):
        rock = o3d.geometry.TriangleMesh.create_sphere(1.0, resolution=20)
        radii = rng.uniform(0.12, 0.3, 3)
        verts = np.asarray(rock.vertices) * radii
        rock.vertices = o3d.utility.Vector3dVector(verts)
        rock.translate((*rng.uniform(-0.5, 0.5, 2), radii[2] * 0.6))
        mesh += rock
    return mesh


def look_at(centre: F64, target: F64) -> tuple[F64, F64]:
    """World-to-camera rotation and translation of an upright camera at ``centre``."""
    z = target - centre
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    rot = np.stack([x, y, z])
    return rot, -rot @ centre


def orbit(n: int, radius: float = 2.2, height: float = 1.3, arc: float = 1.2) -> list[F64]:
    """Camera centres on an arc (radians) around the origin."""
    angles = np.linspace(-arc / 2, arc / 2, n)
    return [np.array([radius * np.cos(a), radius * np.sin(a), height]) for a in angles]


def render(
    mesh: o3d.geometry.TriangleMesh,
    k: F64,
    size: tuple[int, int],
    rot: F64,
    trans: F64,
    seed: int = 0,
) -> npt.NDArray[np.uint8]:
    """Ray-cast an RGB image of ``mesh`` (texture from 3D position, simple shading)."""
    w, h = size
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    pix = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], axis=1)
    dirs_cam = pix @ np.linalg.inv(k).T
    dirs = dirs_cam @ rot
    origin = -rot.T @ trans
    rays = np.hstack([np.broadcast_to(origin, dirs.shape), dirs]).astype(np.float32)
    hit = scene.cast_rays(o3d.core.Tensor(rays))
    t = hit['t_hit'].numpy()
    normals = hit['primitive_normals'].numpy()
    ok = np.isfinite(t)
    pts = origin + dirs[ok] * t[ok, None]
    colour = texture(pts, seed).astype(np.float64)
    light = np.array([0.3, 0.2, 0.93])
    shade = 0.5 + 0.5 * np.abs(normals[ok] @ light)
    img = np.zeros((h * w, 3), dtype=np.uint8)
    img[ok] = np.clip(colour * shade[:, None], 0, 255).astype(np.uint8)
    return img.reshape(h, w, 3)
