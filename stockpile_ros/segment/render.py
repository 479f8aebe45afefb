"""A picture of the segmented pile, the labelled mesh ray-cast from above.

One colour per rock (open3d's CPU ``RaycastingScene``, no display or GPU needed).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ['label_colours', 'render_labels']


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


def render_labels(
    vertices: npt.ArrayLike,
    faces: npt.ArrayLike,
    labels: npt.ArrayLike,
    width: int = 960,
    height: int = 720,
    azimuth_deg: float = -60.0,
    elevation_deg: float = 45.0,
) -> npt.NDArray[np.uint8]:
    """Perspective view of the mesh coloured by face label, shaded by a light at the camera.

    Returns:
        ``height x width x 3`` RGB image; background white.

    """
    import open3d

    o3d: Any = open3d

    v = np.asarray(vertices, dtype=np.float32)
    f = np.asarray(faces, dtype=np.uint32)
    lab = np.asarray(labels, dtype=np.int64)
    image = np.full((height, width, 3), 255, dtype=np.uint8)
    if len(f) == 0:
        return image
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(v), o3d.core.Tensor(f))
    lo, hi = v.min(axis=0), v.max(axis=0)
    centre = 0.5 * (lo + hi)
    radius = float(np.linalg.norm(hi - lo)) * 0.5 or 1.0
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    direction = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    fov = 40.0
    eye = centre + direction * radius / np.sin(np.radians(fov / 2)) * 1.05
    rays = scene.create_rays_pinhole(
        fov_deg=fov,
        center=centre.tolist(),
        eye=eye.tolist(),
        up=[0, 0, 1],
        width_px=width,
        height_px=height,
    )
    hit = scene.cast_rays(rays)
    prim = hit['primitive_ids'].numpy().astype(np.int64)
    normal = hit['primitive_normals'].numpy()
    ray_dir = rays.numpy()[..., 3:]
    ray_dir = ray_dir / np.linalg.norm(ray_dir, axis=-1, keepdims=True)
    ok = prim < len(f)
    colours = label_colours(int(lab.max()) + 1 if len(lab) else 1)
    shade = 0.3 + 0.7 * np.abs(np.einsum('ijk,ijk->ij', normal, ray_dir))
    rgb = colours[lab[prim[ok]]].astype(np.float64) * shade[ok][:, None]
    image[ok] = np.clip(rgb, 0, 255).astype(np.uint8)
    return image
