"""The report's pictures: numbered render, outlined keyframe photo, gradation with its band.

The render has a scale bar; the keyframe photo has the rocks outlined; the gradation curve has
its confidence band, the class limits and the fitted curve.

Numbers are drawn where each rock is seen (the median pixel of its ray-cast footprint), so the
table's ids can be found on the pictures; rocks seen on under ``PARTLY_SEEN`` of their surface are
marked ``!`` and outlined in orange on both pictures, as in the table.
"""

from __future__ import annotations

import io
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..artefacts import KeyframePose
from ..result import GradationRecord, RockRecord
from .measure import PARTLY_SEEN
from .qa import LENGTH_UNITS
from .render import Pinhole, label_colours, overview_camera, raycast_labels

__all__ = ['KeyframeView', 'find_keyframe', 'gradation_png', 'keyframe_png', 'render_png']

_LOW = '#ff7f0e'


@dataclass(frozen=True)
class KeyframeView:
    """One keyframe photo and its camera in the stockpile frame.

    Attributes:
        file: The PNG's path.
        camera: Pinhole camera (distortion removed from the photo when it had any).
        stamp_ns: Its stamp.
        distortion: The photo's distortion coefficients (OpenCV order; empty for none).

    """

    file: Path
    camera: Pinhole
    stamp_ns: int
    distortion: tuple[float, ...] = ()


def _figure(width_px: int, height_px: int, dpi: int = 100) -> Any:
    import matplotlib

    matplotlib.use('Agg')
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_px / dpi, height_px / dpi), dpi=dpi)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_axis_off()
    return fig, ax


def _png_bytes(fig: Any) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format='png')
    return buf.getvalue()


def _label_rocks(ax: Any, seen: npt.NDArray[np.int64], rocks: Sequence[RockRecord]) -> None:
    """Write each rock's id at the median pixel of its footprint (rocks not in view get none)."""
    # The pixels grouped by label once: a comparison of the whole image per rock cost seconds
    # on a pile of hundreds.
    flat = seen.ravel()
    order = np.argsort(flat, kind='stable')
    ids = np.asarray([rock.id for rock in rocks], dtype=flat.dtype)
    lo = np.searchsorted(flat[order], ids, side='left')
    hi = np.searchsorted(flat[order], ids, side='right')
    for rock, start, stop in zip(rocks, lo, hi, strict=True):
        ys, xs = np.divmod(order[start:stop], seen.shape[1])
        if len(xs) < 4:
            continue
        low = rock.visible_fraction < PARTLY_SEEN
        ax.text(
            float(np.median(xs)),
            float(np.median(ys)),
            f'{rock.id}{"!" if low else ""}',
            ha='center',
            va='center',
            fontsize=9,
            weight='bold',
            color='black',
            bbox={
                'boxstyle': 'round,pad=0.15',
                'lw': 1.5 if low else 0.5,
                'fc': 'white',
                'ec': _LOW if low else 'black',
                'alpha': 0.85,
            },
        )


def _outlines(seen: npt.NDArray[np.int64], ids: set[int]) -> npt.NDArray[np.bool_]:
    """Pixels on the border of the footprint of any rock in ``ids``."""
    edge = np.zeros(seen.shape, dtype=bool)
    right = seen[:, 1:] != seen[:, :-1]
    down = seen[1:, :] != seen[:-1, :]
    mine = np.isin(seen, list(ids)) if ids else np.zeros(seen.shape, dtype=bool)
    edge[:, 1:] |= right & (mine[:, 1:] | mine[:, :-1])
    edge[1:, :] |= down & (mine[1:, :] | mine[:-1, :])
    return edge


def _nice(length: float) -> float:
    """Largest of 1, 2, 5 x 10^k not above ``length``."""
    exp = math.floor(math.log10(length))
    return max(m * 10.0**exp for m in (1, 2, 5) if m * 10.0**exp <= length)


def _scale_bar(
    camera: Pinhole, vertices: npt.NDArray[np.float64], unit: str
) -> tuple[npt.NDArray[np.float64], float] | None:
    """Pixel ends and length of a bar of a round length on the ground at the pile's front foot."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    centre = 0.5 * (lo + hi)
    towards = camera.position - centre
    towards[2] = 0.0
    norm = float(np.linalg.norm(towards)) or 1.0
    radius = 0.5 * float(np.hypot(*(hi - lo)[:2]))
    foot = centre + towards / norm * radius * 0.9
    foot[2] = 0.0
    right = camera.rotation[:, 0].copy()
    right[2] = 0.0
    right /= float(np.linalg.norm(right)) or 1.0
    factor = LENGTH_UNITS[unit]
    length = _nice(0.4 * radius / factor) * factor
    uv, front = camera.project([foot - 0.5 * length * right, foot + 0.5 * length * right])
    return (uv, length / factor) if front.all() else None


def _draw_bar(ax: Any, uv: npt.NDArray[np.float64], length: float, unit: str) -> None:
    (x0, y0), (x1, y1) = uv
    ax.plot([x0, x1], [y0, y1], color='black', lw=4, solid_capstyle='butt')
    ax.plot([x0, x1], [y0, y1], color='white', lw=1.5, solid_capstyle='butt')
    ax.text(
        0.5 * (x0 + x1),
        0.5 * (y0 + y1) + 14,
        f'{length:g} {unit} (on the ground)',
        ha='center',
        va='top',
        fontsize=9,
        bbox={'fc': 'white', 'ec': 'none', 'alpha': 0.8},
    )


def render_png(
    vertices: npt.NDArray[np.float64],
    faces: npt.NDArray[np.int64],
    labels: npt.NDArray[np.integer[Any]],
    rocks: Sequence[RockRecord],
    unit: str | None,
) -> bytes:
    """Draw the pile from above-front: one colour per rock, ids, low-visibility marks, scale bar.

    Args:
        vertices: Mesh vertices [m, or model units].
        faces: Triangles.
        labels: Face labels.
        rocks: The report's rocks.
        unit: Display length unit of the scale bar; None (no metric scale): no bar.

    """
    # Framed on the rocks: the ground ring Poisson leaves round a pile would take most of the view.
    on_rocks = np.unique(faces[labels > 0]) if (labels > 0).any() else np.arange(len(vertices))
    cam = overview_camera(vertices[on_rocks])
    seen, shade = raycast_labels(vertices, faces, labels, cam)
    image = np.full((cam.height, cam.width, 3), 255, dtype=np.uint8)
    ok = seen >= 0
    colours = label_colours(int(labels.max()) + 1 if len(labels) else 1)
    image[ok] = np.clip(colours[seen[ok]] * (0.3 + 0.7 * shade[ok])[:, None], 0, 255)
    low = {r.id for r in rocks if r.visible_fraction < PARTLY_SEEN}
    image[_outlines(seen, low)] = (255, 127, 14)
    bar = _scale_bar(cam, vertices[on_rocks], unit) if unit is not None and len(on_rocks) else None
    keep = seen > 0
    if bar is not None:
        for x, y in np.clip(bar[0], 0, [cam.width - 1, cam.height - 1]).astype(int):
            keep[min(y + 30, cam.height - 1), x] = True
    x0, x1, y0, y1 = _crop(keep, cam.width, cam.height)
    fig, ax = _figure(x1 - x0, y1 - y0)
    ax.imshow(image)
    _label_rocks(ax, seen, rocks)
    if bar is not None and unit is not None:
        _draw_bar(ax, bar[0], bar[1], unit)
    else:
        ax.text(x0 + 10, y1 - 10, 'no metric scale: no scale bar', fontsize=10, va='bottom')
    ax.set_xlim(x0 - 0.5, x1 - 0.5)
    ax.set_ylim(y1 - 0.5, y0 - 0.5)
    return _png_bytes(fig)


def _quat_matrix(q: list[float]) -> npt.NDArray[np.float64]:
    from scipy.spatial.transform import Rotation

    matrix: npt.NDArray[np.float64] = Rotation.from_quat(q).as_matrix()
    return matrix


def find_keyframe(
    keyframes_dir: Path | None,
    poses: Sequence[KeyframePose],
    centroids: npt.ArrayLike,
) -> tuple[KeyframeView | None, str]:
    """Pick the keyframe that sees the most rock centroids, or return None and why there is none.

    Args:
        keyframes_dir: The work folder's ``keyframes/`` (``keyframes.jsonl`` and PNGs), or None.
        poses: The report's keyframes: stamp and camera-to-stockpile pose of each one used.
        centroids: Rock centroids in the stockpile frame.

    """
    if not poses:
        return None, 'no keyframe poses in the mesh information (mesh.json)'
    index = keyframes_dir / 'keyframes.jsonl' if keyframes_dir is not None else None
    if index is None or not index.is_file():
        return None, f'no keyframe photos beside the mesh ({index or "no work folder"})'
    by_stamp: dict[int, dict[str, Any]] = {}
    for line in index.read_text().splitlines():
        if line.strip():
            entry = json.loads(line)
            by_stamp[int(entry['stamp_ns'])] = entry
    best: tuple[tuple[int, float], KeyframeView] | None = None
    pts = np.asarray(centroids, dtype=np.float64).reshape(-1, 3)
    for pose in poses:
        entry = by_stamp.get(pose.stamp_ns)
        if (
            entry is None
            or not entry.get('camera')
            or not (keyframes_dir / entry['file']).is_file()
        ):
            continue
        cam = entry['camera']
        camera = Pinhole(
            np.asarray(cam['k'], dtype=np.float64).reshape(3, 3),
            _quat_matrix(pose.orientation_xyzw),
            np.asarray(pose.position, dtype=np.float64),
            int(cam['width']),
            int(cam['height']),
        )
        uv, front = camera.project(pts)
        inside = front & (uv[:, 0] >= 0) & (uv[:, 0] < camera.width)
        inside &= (uv[:, 1] >= 0) & (uv[:, 1] < camera.height)
        view = KeyframeView(
            keyframes_dir / entry['file'],
            camera,
            pose.stamp_ns,
            tuple(float(x) for x in cam.get('d') or ()),
        )
        # Most rocks in frame first; then the nearest camera, where the rocks look largest.
        distance = float(np.linalg.norm(camera.position - pts.mean(axis=0))) if len(pts) else 0.0
        rank = (int(inside.sum()), -distance)
        if best is None or rank > best[0]:
            best = (rank, view)
    if best is None:
        return None, 'no keyframe photo matches the keyframes of the mesh (by stamp)'
    return best[1], ''


def keyframe_png(
    view: KeyframeView,
    vertices: npt.NDArray[np.float64],
    faces: npt.NDArray[np.int64],
    labels: npt.NDArray[np.integer[Any]],
    rocks: Sequence[RockRecord],
) -> bytes:
    """Draw each rock's visible outline and id on the keyframe photo (ray-cast from its camera)."""
    import cv2

    photo = cv2.imread(str(view.file), cv2.IMREAD_COLOR)
    if photo is None:
        raise OSError(f'cannot read {view.file}')
    photo = cv2.cvtColor(photo, cv2.COLOR_BGR2RGB)
    cam = view.camera
    if photo.shape[:2] != (cam.height, cam.width):
        photo = cv2.resize(photo, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
    if any(abs(x) > 0 for x in view.distortion):
        photo = cv2.undistort(photo, cam.k, np.asarray(view.distortion, dtype=np.float64))
    seen, _ = raycast_labels(vertices, faces, labels, cam)
    ids = {r.id for r in rocks}
    low = {r.id for r in rocks if r.visible_fraction < PARTLY_SEEN}
    image = photo.copy()
    image[_outlines(seen, ids - low)] = (255, 255, 255)
    image[_outlines(seen, low)] = (255, 127, 14)
    x0, x1, y0, y1 = _crop(seen > 0, cam.width, cam.height)
    zoom = max(1.0, 900.0 / (x1 - x0))
    fig, ax = _figure(int((x1 - x0) * zoom), int((y1 - y0) * zoom))
    ax.imshow(image)
    _label_rocks(ax, seen, rocks)
    ax.set_xlim(x0 - 0.5, x1 - 0.5)
    ax.set_ylim(y1 - 0.5, y0 - 0.5)
    return _png_bytes(fig)


def _crop(mask: npt.NDArray[np.bool_], width: int, height: int) -> tuple[int, int, int, int]:
    """Pixel box round ``mask`` with a 15 % margin, the image's aspect ratio, inside the image."""
    ys, xs = np.nonzero(mask)
    if len(xs) == 0:
        return 0, width, 0, height
    cx, cy = 0.5 * (xs.min() + xs.max()), 0.5 * (ys.min() + ys.max())
    half_w = max(0.5 * (xs.max() - xs.min()), 0.5 * (ys.max() - ys.min()) * width / height)
    half_w = min(1.15 * half_w + 10, 0.5 * width)
    half_h = half_w * height / width
    x0 = int(np.clip(cx - half_w, 0, width - 2 * half_w))
    y0 = int(np.clip(cy - half_h, 0, height - 2 * half_h))
    return x0, int(x0 + 2 * half_w), y0, int(y0 + 2 * half_h)


def gradation_png(grad: GradationRecord, unit: str | None) -> bytes:
    """Plot percent passing by mass and by count against size, with interval band, limits, fit.

    Args:
        grad: The report's gradation.
        unit: Display length unit; None for model units.

    """
    import matplotlib

    matplotlib.use('Agg')
    from matplotlib.figure import Figure

    spec = grad.spec
    factor = LENGTH_UNITS[unit] if unit else 1.0
    label = unit or 'model units'
    fig = Figure(figsize=(7.5, 4.6), dpi=110)
    ax = fig.add_subplot(1, 1, 1)
    sizes = np.asarray(grad.sizes, dtype=np.float64) / factor
    band = [
        (int(key[1:]), lo, hi)
        for key, (lo, hi) in grad.intervals.mass.items()
        if lo is not None and hi is not None
    ]
    if band:
        ax.fill_betweenx(
            [pct for pct, _, _ in band],
            [lo / factor for _, lo, _ in band],
            [hi / factor for _, _, hi in band],
            color='tab:blue',
            alpha=0.18,
            lw=0,
            label=f'{grad.intervals.confidence:.0%} interval of D (bootstrap + scale)',
        )
    if len(sizes):
        ax.plot(sizes, grad.percent_passing_mass, 'o-', color='tab:blue', ms=4, label='by mass')
        ax.plot(sizes, grad.percent_passing_count, 's--', color='tab:gray', ms=3, label='by count')
        ax.set_xscale('log')
    fit = grad.rosin_rammler
    if fit and len(sizes):
        xs = np.geomspace(sizes[0] * 0.8, sizes[-1] * 1.1, 100)
        ax.plot(
            xs,
            100 * (1 - np.exp(-((xs * factor / fit.d_c) ** fit.n))),
            ':',
            color='tab:green',
            label=f'Rosin-Rammler d_c {fit.d_c / factor:.3g} {label}, n {fit.n:.2f}',
        )
    for row in spec.limits:
        pct = int(row.key[1:])
        ends = [x / factor for x in (row.min, row.max) if x is not None]
        colour = {'pass': 'tab:green', 'fail': 'tab:red'}.get(row.status, _LOW)
        ax.plot(ends, [pct] * len(ends), '|-', color=colour, lw=2, ms=14)
    if spec.limits:
        ax.plot(
            [],
            [],
            '|-',
            color='tab:red',
            label=f'class {spec.class_name} limits ({spec.basis}; green pass, orange '
            'undecided, red fail)',
        )
    ax.set_xlabel(f'size {grad.size_measure} [{label}]')
    ax.set_ylabel('percent passing [%]')
    ax.set_ylim(0, 102)
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(loc='upper left', fontsize=7)
    fig.tight_layout()
    return _png_bytes(fig)
