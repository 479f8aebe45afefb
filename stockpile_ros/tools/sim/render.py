"""Ray-cast rendering of a pile on CPU with open3d's RaycastingScene.

One primary ray per pixel finds the surface; its colour is a solid texture evaluated at the hit
point, lit by a sun (Lambert, with a shadow ray towards the sun) plus sky ambient light. Every hit
also reports which rock and which rock triangle it saw: that is how the truth knows what was seen.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import open3d as o3d

from ...camera import CameraModel
from .pile import PlacedRock
from .texture import BoardTexture, GroundTexture, RockTextures

__all__ = [
    'BOARD_LABEL',
    'SKY_LABEL',
    'Lighting',
    'RenderResult',
    'Renderer',
    'linear_to_srgb',
    'linear_to_srgb8',
    'pixel_rays',
]

# Geometry ids, in the order the geometries are added (the ground plane is 0).
_ROCKS, _BOARD = 1, 2
# Label of pixels that see the board or the sky: not a rock, not the bare ground.
BOARD_LABEL = -1
SKY_LABEL = -2


@dataclass(frozen=True)
class Lighting:
    """Sun and sky.

    Attributes:
        sun_direction: Unit vector from the scene towards the sun (world frame).
        sun: Irradiance of direct sun (albedo 1, normal incidence -> this linear value).
        ambient: Irradiance from the sky on an unshadowed surface.
        sky_colour: Linear RGB of pixels that hit nothing.

    """

    sun_direction: tuple[float, float, float] = (0.45, -0.35, 0.82)
    sun: float = 1.1
    ambient: float = 0.35
    sky_colour: tuple[float, float, float] = (0.55, 0.65, 0.8)


@dataclass
class RenderResult:
    """One rendered view.

    Attributes:
        linear: HxWx3 float32 linear RGB radiance (noise-free).
        labels: HxW int32: rock id, 0 ground, -1 board, -2 sky.
        depth: HxW float32 distance along the optical axis [m], inf for sky.
        rock_triangles: Indices (into the concatenated rock faces) of every rock triangle hit.

    """

    linear: npt.NDArray[np.float32]
    labels: npt.NDArray[np.int32]
    depth: npt.NDArray[np.float32]
    rock_triangles: npt.NDArray[np.int64]


def pixel_rays(camera: CameraModel) -> npt.NDArray[np.float32]:
    """Unnormalised ray directions (HxWx3, optical frame, z = 1) through every pixel centre."""
    u, v = np.meshgrid(np.arange(camera.width), np.arange(camera.height))
    x = (u - camera.cx) / camera.fx
    y = (v - camera.cy) / camera.fy
    return np.stack([x, y, np.ones_like(x)], axis=-1).astype(np.float32)


def _srgb_table(levels: int) -> npt.NDArray[np.float32]:
    x = np.linspace(0.0, 1.0, levels)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.asarray(srgb * 255.0, dtype=np.float32)


# Linear -> sRGB through a table: a power per pixel costs more than the whole shading.
_SRGB_LEVELS = 8192
_SRGB = _srgb_table(_SRGB_LEVELS)


def linear_to_srgb(linear: npt.NDArray[np.floating]) -> npt.NDArray[np.float32]:
    """Encode linear RGB in [0, 1] (clipped) as sRGB levels 0..255, as float32."""
    scaled = np.clip(linear, 0.0, 1.0) * np.float32(_SRGB_LEVELS - 1) + np.float32(0.5)
    return np.asarray(_SRGB[scaled.astype(np.int32)])


def linear_to_srgb8(linear: npt.NDArray[np.floating]) -> npt.NDArray[np.uint8]:
    """Encode linear RGB in [0, 1] as 8-bit sRGB."""
    return np.asarray(np.round(linear_to_srgb(linear)), dtype=np.uint8)


class Renderer:
    """Renders views of a scene of rocks, ground and an optional board.

    Args:
        rocks: The placed rocks.
        camera: Pinhole camera (distortion is ignored).
        rock_textures: Solid textures of the rocks.
        ground: Ground texture.
        board: The board lying on the ground, or None.
        lighting: Sun and sky.
        shadows: Cast a shadow ray per lit hit.
        threads: Threads for ray casting (0: all cores).
        ground_half: Half side of the square ground plane [m].

    """

    def __init__(
        self,
        rocks: list[PlacedRock],
        camera: CameraModel,
        rock_textures: RockTextures,
        ground: GroundTexture,
        board: BoardTexture | None = None,
        lighting: Lighting | None = None,
        shadows: bool = True,
        threads: int = 0,
        ground_half: float = 60.0,
    ):
        self.camera = camera
        self.rock_textures = rock_textures
        self.ground = ground
        self.board = board
        self.board_image = board.image() if board is not None else None
        self.lighting = lighting or Lighting()
        sun = np.asarray(self.lighting.sun_direction, dtype=np.float64)
        self.sun = (sun / np.linalg.norm(sun)).astype(np.float32)
        self.shadows = shadows
        self.threads = threads
        rays_cam = pixel_rays(camera).reshape(-1, 3)
        self._cam_x = np.ascontiguousarray(rays_cam[:, 0])
        self._cam_y = np.ascontiguousarray(rays_cam[:, 1])
        self._rays = np.empty((len(rays_cam), 6), dtype=np.float32)
        if rocks:
            allv = np.concatenate([r.mesh.vertices for r in rocks])
            lo, hi = allv.min(axis=0), allv.max(axis=0)
            self._rock_box: tuple[float, float, float, float] | None = (lo[0], lo[1], hi[0], hi[1])
            self._rock_top = float(hi[2])
        else:
            self._rock_box, self._rock_top = None, 0.0

        verts, faces, labels = [], [], []
        offset = 0
        for rock in rocks:
            verts.append(rock.mesh.vertices)
            faces.append(rock.mesh.faces + offset)
            labels.append(np.full(len(rock.mesh.faces), rock.id, dtype=np.int32))
            offset += len(rock.mesh.vertices)
        self.face_labels = np.concatenate(labels) if labels else np.zeros(0, dtype=np.int32)
        self.scene = o3d.t.geometry.RaycastingScene()
        g = ground_half
        ground_v = np.array([[-g, -g, 0.0], [g, -g, 0.0], [g, g, 0.0], [-g, g, 0.0]])
        self._add(ground_v, np.array([[0, 1, 2], [0, 2, 3]]))
        if rocks:
            self._add(np.concatenate(verts), np.concatenate(faces))
        else:
            self._add(np.full((3, 3), -1e6), np.array([[0, 1, 2]]))
        if board is not None:
            # A sheet of paper: lifted off the ground so that it always wins the depth test.
            quad = board.corner_quad() + np.array([0.0, 0.0, 0.0005])
            self._add(quad, np.array([[0, 1, 2], [0, 2, 3]]))

    def _add(self, vertices: npt.NDArray[np.float64], faces: npt.NDArray[np.int64]) -> None:
        self.scene.add_triangles(
            o3d.core.Tensor.from_numpy(np.ascontiguousarray(vertices, dtype=np.float32)),
            o3d.core.Tensor.from_numpy(np.ascontiguousarray(faces, dtype=np.uint32)),
        )

    def render(self, position: npt.ArrayLike, rotation: npt.NDArray[np.float64]) -> RenderResult:
        """Render the view from optical centre ``position`` with camera axes ``rotation`` (columns).

        Args:
            position: Optical centre in the world frame [m].
            rotation: 3x3 camera-to-world rotation (optical frame: x right, y down, z forward).

        """
        h, w = self.camera.height, self.camera.width
        # Python floats keep every product float32 (numpy 2 promotes by float64 scalars).
        o = [float(v) for v in np.asarray(position, dtype=np.float64)]
        r = [[float(v) for v in row] for row in np.asarray(rotation, dtype=np.float64)]
        # Long 1D arrays per coordinate throughout: numpy is slow on Nx3 arrays.
        cx, cy = self._cam_x, self._cam_y
        d = [r[k][0] * cx + r[k][1] * cy + r[k][2] for k in range(3)]
        for k in range(3):
            self._rays[:, k] = o[k]
            self._rays[:, 3 + k] = d[k]
        hit = self.scene.cast_rays(o3d.core.Tensor.from_numpy(self._rays), nthreads=self.threads)
        t = hit['t_hit'].numpy()
        geom = hit['geometry_ids'].numpy()
        prim = hit['primitive_ids'].numpy()
        normals = hit['primitive_normals'].numpy()

        found = np.isfinite(t)
        # Work on the hits only; when every ray hits (the usual view of a pile), that is all rays
        # and no gather is needed.
        every = bool(found.all())
        idx = np.flatnonzero(found)

        def hits(a: npt.NDArray[Any]) -> npt.NDArray[Any]:
            return a if every else a[idx]

        th = hits(t)
        dh = [hits(d[k]) for k in range(3)]
        p = [o[k] + dh[k] * th for k in range(3)]
        g = hits(geom)
        labels_h = np.zeros(len(th), dtype=np.int32)
        # Ground colour everywhere first (one lookup, no gather): rocks and board overwrite theirs.
        albedo = self.ground.albedo(p[0], p[1])
        on_rock = np.flatnonzero(g == _ROCKS)
        rock_prims = hits(prim)[on_rock].astype(np.int64)
        rock_ids = self.face_labels[rock_prims]
        labels_h[on_rock] = rock_ids
        albedo[on_rock] = self.rock_textures.albedo(
            p[0][on_rock], p[1][on_rock], p[2][on_rock], rock_ids.astype(np.int64)
        )
        if self.board is not None and self.board_image is not None:
            on_board = np.flatnonzero(g == _BOARD)
            labels_h[on_board] = BOARD_LABEL
            albedo[on_board] = self.board.lookup(self.board_image, p[0][on_board], p[1][on_board])

        n = [hits(normals[:, k]) for k in range(3)]
        # Stored face normals may point either way; light the side the camera sees.
        toward = n[0] * dh[0] + n[1] * dh[1] + n[2] * dh[2]
        sign = np.where(toward > 0, np.float32(-1.0), np.float32(1.0))
        sun = [float(v) for v in self.sun]
        lit = sign * (n[0] * sun[0] + n[1] * sun[1] + n[2] * sun[2]) > 0
        if self.shadows:
            self._shadow(p, n, sign, lit)
        # Shading normals: the face normal, tilted on rocks by the surface relief.
        shade_n = [sign * n[k] for k in range(3)]
        if len(on_rock):
            self._add_relief(shade_n, [p[k][on_rock] for k in range(3)], on_rock, rock_ids)
        cos_sun = shade_n[0] * sun[0] + shade_n[1] * sun[1] + shade_n[2] * sun[2]
        lit &= cos_sun > 0
        irradiance = self.lighting.ambient * (0.75 + 0.25 * shade_n[2])
        irradiance += self.lighting.sun * np.where(lit, cos_sun, np.float32(0.0))
        shaded = albedo * irradiance[:, None]
        if every:
            linear = shaded
            labels, depth = labels_h, th
        else:
            linear = np.empty((len(t), 3), dtype=np.float32)
            linear[:] = np.asarray(self.lighting.sky_colour, dtype=np.float32)
            linear[idx] = shaded
            labels = np.full(len(t), SKY_LABEL, dtype=np.int32)
            labels[idx] = labels_h
            depth = np.full(len(t), np.inf, dtype=np.float32)
            depth[idx] = th
        # Rays have unit z in the optical frame, so the hit distance t is the depth.
        return RenderResult(
            linear=linear.reshape(h, w, 3),
            labels=labels.reshape(h, w),
            depth=np.array(depth, dtype=np.float32).reshape(h, w),
            rock_triangles=np.unique(rock_prims),
        )

    def _add_relief(
        self,
        normals: list[npt.NDArray[np.float32]],
        points: list[npt.NDArray[np.float32]],
        rows: npt.NDArray[np.intp],
        rock_ids: npt.NDArray[np.int32],
    ) -> None:
        """Tilt the unit ``normals`` at ``rows`` (rock hits at ``points``) by the rock relief."""
        grad = self.rock_textures.relief(points[0], points[1], points[2], rock_ids.astype(np.int64))
        nr = [normals[k][rows] for k in range(3)]
        along = grad[0] * nr[0] + grad[1] * nr[1] + grad[2] * nr[2]
        # Only the gradient's part along the surface tilts the normal (a height field on it).
        tilted = [nr[k] - (grad[k] - along * nr[k]) for k in range(3)]
        norm = np.sqrt(tilted[0] ** 2 + tilted[1] ** 2 + tilted[2] ** 2)
        for k in range(3):
            normals[k][rows] = tilted[k] / norm

    def _shadow(
        self,
        p: list[npt.NDArray[np.float32]],
        n: list[npt.NDArray[np.float32]],
        sign: npt.NDArray[np.float32],
        lit: npt.NDArray[np.bool_],
    ) -> None:
        """Clear ``lit`` where the way to the sun is blocked by a rock.

        Only rocks cast shadows (ground and board are flat), so a shadow ray is cast only where its
        path up to the rocks' top height crosses the rocks' bounding box in x, y.
        """
        if self._rock_box is None:
            return
        (x0, y0, x1, y1), top = self._rock_box, self._rock_top
        sun = [float(v) for v in self.sun]
        reach = np.maximum(top - p[2], np.float32(0.0)) / max(sun[2], 1e-3)
        ex, ey = p[0] + sun[0] * reach, p[1] + sun[1] * reach
        may = (
            lit
            & (np.maximum(p[0], ex) >= x0)
            & (np.minimum(p[0], ex) <= x1)
            & (np.maximum(p[1], ey) >= y0)
            & (np.minimum(p[1], ey) <= y1)
        )
        cand = np.flatnonzero(may)
        if len(cand) == 0:
            return
        rays = np.empty((len(cand), 6), dtype=np.float32)
        for k in range(3):
            rays[:, k] = p[k][cand] + 1e-3 * sign[cand] * n[k][cand]
            rays[:, 3 + k] = sun[k]
        blocked = self.scene.test_occlusions(
            o3d.core.Tensor.from_numpy(rays), nthreads=self.threads
        )
        lit[cand[blocked.numpy()]] = False
