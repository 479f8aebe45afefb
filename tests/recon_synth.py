"""Small synthetic scenes for the reconstruction tests: textured ground, rocks, ray-cast views."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
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


def seen_points(
    mesh: o3d.geometry.TriangleMesh, k: F64, size: tuple[int, int], rot: F64, centre: F64
) -> F64:
    """Scene points under a 16 x 12 grid of pixels of a view (the corners a selector tracks)."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    u, v = np.meshgrid(np.linspace(0, size[0] - 1, 16), np.linspace(0, size[1] - 1, 12))
    pixels = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], axis=1)
    dirs = pixels @ np.linalg.inv(k).T @ rot
    rays = np.hstack([np.broadcast_to(centre, dirs.shape), dirs]).astype(np.float32)
    hit = scene.cast_rays(o3d.core.Tensor(rays))['t_hit'].numpy()
    ok = np.isfinite(hit)
    return np.asarray(centre + dirs[ok] * hit[ok, None], dtype=np.float64)


def viewing_angle(points: F64, a: F64, b: F64) -> float:
    """Median over ``points`` of the angle [deg] between the rays from centres ``a`` and ``b``."""
    ray_a, ray_b = points - a, points - b
    cos = np.sum(ray_a * ray_b, axis=1)
    cos /= np.linalg.norm(ray_a, axis=1) * np.linalg.norm(ray_b, axis=1)
    return float(np.degrees(np.median(np.arccos(np.clip(cos, -1.0, 1.0)))))


def orbit(n: int, radius: float = 2.2, height: float = 1.3, arc: float = 1.2) -> list[F64]:
    """Camera centres on an arc (radians) around the origin."""
    angles = np.linspace(-arc / 2, arc / 2, n)
    return [np.array([radius * np.cos(a), radius * np.sin(a), height]) for a in angles]


@dataclass(frozen=True)
class Decal:
    """A printed marker lying on the ground (z = 0), its white margin around it.

    Attributes:
        image: The marker, black square edge to edge, one grey level a cell.
        centre: Its centre (x, y) [m].
        size: Edge of its black square [m].
        margin: White border beyond it, in marker edges.

    """

    image: npt.NDArray[np.uint8]
    centre: tuple[float, float]
    size: float
    margin: float = 0.25


def marker_decal(
    dictionary: str, marker_id: int, size: float, centre: tuple[float, float]
) -> Decal:
    """An ArUco or AprilTag marker as OpenCV draws it, to lay on the ground."""
    code = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    cells = code.markerSize + 2
    return Decal(cv2.aruco.generateImageMarker(code, marker_id, cells), centre, size)


def _decal_grey(decal: Decal, x: F64, y: F64) -> F64:
    """Grey level of ground points (x, y) under the decal: paper, ink, NaN off it."""
    u = (x - decal.centre[0]) / decal.size + 0.5
    v = 0.5 - (y - decal.centre[1]) / decal.size
    grey = np.full(u.shape, np.nan)
    paper = (np.minimum(u, v) > -decal.margin) & (np.maximum(u, v) < 1 + decal.margin)
    grey[paper] = 235.0
    ink = paper & (np.minimum(u, v) >= 0) & (np.maximum(u, v) < 1)
    n = decal.image.shape[0]
    rows = np.clip((v[ink] * n).astype(int), 0, n - 1)
    cols = np.clip((u[ink] * n).astype(int), 0, n - 1)
    grey[ink] = np.where(decal.image[rows, cols] > 127, 235.0, 20.0)
    return grey


def _paint(
    pixels: F64, points: F64, colour: F64, k: F64, rot: F64, origin: F64, decals: tuple[Decal, ...]
) -> None:
    """Colour ground points under each decal with its 8 x 8 sub-pixel average (anti-aliased)."""
    on_ground = np.abs(points[:, 2]) < 1e-4
    offsets = (np.arange(8) + 0.5) / 8 - 0.5
    du, dv = (a.ravel() for a in np.meshgrid(offsets, offsets))
    k_inv = np.linalg.inv(k)
    for decal in decals:
        near = on_ground & np.isfinite(_decal_grey(decal, points[:, 0], points[:, 1]))
        px = pixels[near]
        sub = np.stack([px[:, :1] + du, px[:, 1:2] + dv, np.ones((len(px), du.size))], axis=-1)
        dirs = (sub @ k_inv.T) @ rot
        t = -origin[2] / dirs[..., 2]
        grey = _decal_grey(decal, origin[0] + t * dirs[..., 0], origin[1] + t * dirs[..., 1])
        # Sub-samples off the paper see the ground texture of the pixel's centre.
        here = colour[near].mean(axis=1, keepdims=True)
        grey = np.where(np.isnan(grey), here, grey).mean(axis=1)
        colour[near] = grey[:, None]


def render(
    mesh: o3d.geometry.TriangleMesh,
    k: F64,
    size: tuple[int, int],
    rot: F64,
    trans: F64,
    seed: int = 0,
    decals: tuple[Decal, ...] = (),
) -> npt.NDArray[np.uint8]:
    """Ray-cast an RGB image of ``mesh`` (texture from 3D position, simple shading, decals)."""
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
    _paint(pix[ok, :2], pts, colour, k, rot, origin, decals)
    light = np.array([0.3, 0.2, 0.93])
    shade = 0.5 + 0.5 * np.abs(normals[ok] @ light)
    img = np.zeros((h * w, 3), dtype=np.uint8)
    img[ok] = np.clip(colour * shade[:, None], 0, 255).astype(np.uint8)
    return img.reshape(h, w, 3)
