"""Pictures of the segmented pile: the labelled mesh ray-cast from a pinhole camera.

One colour per rock (open3d's CPU ``RaycastingScene``, no display or GPU needed). The same
:class:`Pinhole` casts the rays and projects points back, so that rock numbers and a scale bar
drawn over a picture land where the rocks are: on a synthetic view from above the pile or on a
keyframe photo (its camera model and pose).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ['Pinhole', 'label_colours', 'overview_camera', 'raycast_labels', 'render_labels']

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Pinhole:
    """A distortion-free pinhole camera, camera-to-world (docs/formats.md conventions).

    Attributes:
        k: 3x3 intrinsic matrix [px].
        rotation: 3x3 rotation of optical-frame vectors (x right, y down, z forward) into the world.
        position: Optical centre in the world [m].
        width: Image width [px].
        height: Image height [px].

    """

    k: F64
    rotation: F64
    position: F64
    width: int
    height: int

    def rays(self) -> npt.NDArray[np.float32]:
        """``height x width x 6`` rays (origin, unit direction) through the pixel centres."""
        u, v = np.meshgrid(np.arange(self.width), np.arange(self.height))
        pix = np.stack([u, v, np.ones_like(u)], axis=-1).astype(np.float64)
        d = pix @ np.linalg.inv(self.k).T @ self.rotation.T
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        origin = np.broadcast_to(self.position, d.shape)
        return np.concatenate([origin, d], axis=-1).astype(np.float32)

    def project(self, points: npt.ArrayLike) -> tuple[F64, npt.NDArray[np.bool_]]:
        """Pixel coordinates of world points and whether each lies in front of the camera."""
        p = (np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.position) @ self.rotation
        front = p[:, 2] > 1e-9
        z = np.where(front, p[:, 2], 1.0)
        uv = (p @ self.k.T)[:, :2] / z[:, None]
        return uv, front


def overview_camera(
    vertices: npt.ArrayLike,
    width: int = 960,
    height: int = 720,
    azimuth_deg: float = -60.0,
    elevation_deg: float = 45.0,
    fov_deg: float = 40.0,
) -> Pinhole:
    """Return a camera looking down at the bounding box centre of the points, all of it in view."""
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    lo, hi = (v.min(axis=0), v.max(axis=0)) if len(v) else (np.zeros(3), np.ones(3))
    centre = 0.5 * (lo + hi)
    radius = float(np.linalg.norm(hi - lo)) * 0.5 or 1.0
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    towards_eye = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    eye = centre + towards_eye * radius / np.sin(np.radians(fov_deg / 2)) * 1.05
    forward = -towards_eye
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    focal = 0.5 * height / np.tan(np.radians(fov_deg / 2))
    k = np.array([[focal, 0, 0.5 * (width - 1)], [0, focal, 0.5 * (height - 1)], [0, 0, 1.0]])
    return Pinhole(k, np.stack([right, down, forward], axis=1), eye, width, height)


def label_colours(n_labels: int) -> npt.NDArray[np.uint8]:
    """RGB colour per label 0..n_labels-1: grey for 0, distinct saturated hues for rocks."""
    colours = np.zeros((max(n_labels, 1), 3), dtype=np.uint8)
    colours[0] = (150, 150, 150)
    k = np.arange(1, max(n_labels, 1))
    hue = (k * 0.618033988749895) % 1.0
    # HSV to RGB with s = 0.65, v = 0.95 (golden-ratio hues stay apart for any count).
    s, v = 0.65, 0.95
    h6 = hue * 6.0
    i = np.floor(h6).astype(int) % 6
    fr = h6 - np.floor(h6)
    p, q, t = v * (1 - s), v * (1 - s * fr), v * (1 - s * (1 - fr))
    table = np.stack(
        [
            np.stack([np.full_like(q, v), t, np.full_like(q, p)], 1),
            np.stack([q, np.full_like(q, v), np.full_like(q, p)], 1),
            np.stack([np.full_like(q, p), np.full_like(q, v), t], 1),
            np.stack([np.full_like(q, p), q, np.full_like(q, v)], 1),
            np.stack([t, np.full_like(q, p), np.full_like(q, v)], 1),
            np.stack([np.full_like(q, v), np.full_like(q, p), q], 1),
        ]
    )
    colours[1:] = (table[i, np.arange(len(k))] * 255).astype(np.uint8)
    return colours


def raycast_labels(
    vertices: npt.ArrayLike, faces: npt.ArrayLike, labels: npt.ArrayLike, camera: Pinhole
) -> tuple[npt.NDArray[np.int64], F64]:
    """Face label seen at each pixel (-1: nothing) and the shading ``|normal . ray|`` there."""
    import open3d

    o3d: Any = open3d
    f = np.asarray(faces, dtype=np.uint32)
    lab = np.asarray(labels, dtype=np.int64)
    seen = np.full((camera.height, camera.width), -1, dtype=np.int64)
    if len(f) == 0:
        return seen, np.zeros(seen.shape)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(vertices, dtype=np.float32)), o3d.core.Tensor(f))
    rays = camera.rays()
    hit = scene.cast_rays(o3d.core.Tensor(rays))
    prim = hit['primitive_ids'].numpy().astype(np.int64)
    normal = hit['primitive_normals'].numpy()
    ok = prim < len(f)
    seen[ok] = lab[prim[ok]]
    shade = np.abs(np.einsum('ijk,ijk->ij', normal, rays[..., 3:]))
    return seen, shade


def render_labels(
    vertices: npt.ArrayLike,
    faces: npt.ArrayLike,
    labels: npt.ArrayLike,
    camera: Pinhole | None = None,
) -> npt.NDArray[np.uint8]:
    """View of the mesh coloured by face label, shaded by a light at the camera.

    Args:
        vertices: Nx3 mesh vertices.
        faces: Mx3 triangles.
        labels: M face labels (0 ground).
        camera: The view (:func:`overview_camera` of the vertices by default).

    Returns:
        ``height x width x 3`` RGB image; background white.

    """
    cam = camera or overview_camera(vertices)
    lab = np.asarray(labels, dtype=np.int64)
    seen, shade = raycast_labels(vertices, faces, lab, cam)
    image = np.full((cam.height, cam.width, 3), 255, dtype=np.uint8)
    ok = seen >= 0
    colours = label_colours(int(lab.max()) + 1 if len(lab) else 1)
    rgb = colours[seen[ok]].astype(np.float64) * (0.3 + 0.7 * shade[ok])[:, None]
    image[ok] = np.clip(rgb, 0, 255).astype(np.uint8)
    return image
