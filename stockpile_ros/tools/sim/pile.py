"""Rock sizes drawn from a gradation, and a pile built by dropping rocks onto what lies below.

Stacking rule: rocks are dropped one at a time, each in a resting orientation (short axis near
vertical), onto the heightfield of the ground and the rocks already placed. A rock comes to rest
where its underside first touches that heightfield, so no two rocks interpenetrate along any
sampled vertical line. Among a few nearby drop points the lowest and most central resting place
wins (rocks settle into hollows), and the rock then slides towards the centre for as long as it
need not climb, so that it ends up touching its neighbours.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
import open3d as o3d

from ...errors import StockpileError
from .rocks import SHAPES, RockMesh, random_rock

__all__ = ['Gradation', 'PileConfig', 'PlacedRock', 'build_pile', 'parse_gradation', 'rotation_z']


@dataclass(frozen=True)
class Gradation:
    """A size distribution as percent passing by mass against the intermediate dimension b.

    Attributes:
        sizes: Increasing sizes b [m].
        percent_passing: Percent of the mass finer than each size, increasing from 0 to 100.

    """

    sizes: tuple[float, ...]
    percent_passing: tuple[float, ...]

    def sample(self, rng: np.random.Generator, count: int) -> npt.NDArray[np.float64]:
        """Draw ``count`` rock sizes b [m] so that their mass follows this gradation.

        The curve is log-linear between its points; by count, a rock of size b is drawn with weight
        proportional to (mass density at b) / b^3, since mass scales with b^3.
        """
        logs = np.log(np.asarray(self.sizes))
        grid = np.linspace(logs[0], logs[-1], 2001)
        pp = np.interp(grid, logs, np.asarray(self.percent_passing))
        mass_density = np.gradient(pp, grid)
        count_density = np.maximum(mass_density, 0.0) * np.exp(-3.0 * grid)
        cdf = np.concatenate([[0.0], np.cumsum(0.5 * (count_density[1:] + count_density[:-1]))])
        cdf /= cdf[-1]
        return np.asarray(np.exp(np.interp(rng.random(count), cdf, grid)))

    def as_dict(self) -> dict[str, list[float]]:
        """JSON-ready form."""
        return {'sizes': list(self.sizes), 'percent_passing_mass': list(self.percent_passing)}


def parse_gradation(text: str) -> Gradation:
    """Parse ``MIN:MAX`` (b range [m], mass evenly spread in log size) or ``D15=0.1,D50=0.15,...``.

    In the second form the given characteristic sizes (percent passing by mass) are extended
    log-linearly to 0 % and 100 % from the two outermost points.

    Raises:
        StockpileError: The text is not a valid gradation.

    """
    try:
        if ':' in text:
            lo, hi = (float(v) for v in text.split(':'))
            points = [(lo, 0.0), (hi, 100.0)]
        else:
            points = []
            for item in text.split(','):
                key, value = item.split('=')
                points.append((float(value), float(key.strip().upper().lstrip('D'))))
            points.sort()
    except ValueError as exc:
        raise StockpileError(
            f'gradation {text!r}: {exc}; use MIN:MAX or D15=..,D50=..,D85=..'
        ) from exc
    sizes = np.array([p[0] for p in points])
    pct = np.array([p[1] for p in points])
    if (
        len(points) < 2
        or np.any(sizes <= 0)
        or np.any(np.diff(sizes) <= 0)
        or np.any(np.diff(pct) <= 0)
    ):
        raise StockpileError(
            f'gradation {text!r}: need two or more increasing sizes and percentages'
        )
    if pct[0] < 0 or pct[-1] > 100:
        raise StockpileError(f'gradation {text!r}: percentages must lie in 0..100')
    logs = np.log(sizes)
    out_sizes, out_pct = list(sizes), list(pct)
    if pct[0] > 0:
        slope = (logs[1] - logs[0]) / (pct[1] - pct[0])
        out_sizes.insert(0, float(np.exp(logs[0] - slope * pct[0])))
        out_pct.insert(0, 0.0)
    if pct[-1] < 100:
        slope = (logs[-1] - logs[-2]) / (pct[-1] - pct[-2])
        out_sizes.append(float(np.exp(logs[-1] + slope * (100 - pct[-1]))))
        out_pct.append(100.0)
    return Gradation(tuple(float(v) for v in out_sizes), tuple(float(v) for v in out_pct))


@dataclass(frozen=True)
class PileConfig:
    """Parameters of a pile.

    Attributes:
        rocks: Number of rocks.
        gradation: Size distribution of b.
        flat_fraction: Share of flat rocks.
        elongated_fraction: Share of elongated rocks.
        spread: Standard deviation of drop points around the pile centre, in units of the radius of
            one layer of the same rocks (smaller piles higher).
        roughness: Radial roughness amplitude (fraction of the radius).
        rounding: How far the rocks' edges are worn round (``random_rock``) [radians; 0: angular
            quarry rock, 0.3: river cobbles].
        subdivisions: Icosphere subdivisions per rock.
        cell: Heightfield cell size [m].
        compactness: Height [m] a rock would rather climb than rest 1 m farther from the centre.

    """

    rocks: int = 12
    gradation: Gradation = field(default_factory=lambda: parse_gradation('0.12:0.3'))
    flat_fraction: float = 0.15
    elongated_fraction: float = 0.15
    spread: float = 0.3
    roughness: float = 0.025
    rounding: float = 0.0
    subdivisions: int = 4
    cell: float = 0.004
    compactness: float = 0.6


@dataclass
class PlacedRock:
    """A rock at rest in the world frame.

    Attributes:
        id: Rock id (1-based).
        shape: Shape class it was drawn from.
        b_nominal: Intermediate dimension drawn from the gradation [m].
        mesh: Closed mesh in the world frame.

    """

    id: int
    shape: str
    b_nominal: float
    mesh: RockMesh


def rotation_z(angle: float) -> npt.NDArray[np.float64]:
    """Rotation by ``angle`` [rad] about z."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _resting_rotation(rng: np.random.Generator) -> npt.NDArray[np.float64]:
    """Random yaw, and a tilt that mostly keeps the short axis near vertical."""
    tilt = rng.normal(0.0, 0.25) if rng.random() < 0.75 else rng.uniform(-0.8, 0.8)
    axis = rng.normal(size=3)
    axis[2] = 0.0
    axis /= np.linalg.norm(axis) + 1e-12
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    tilt_m = np.eye(3) + np.sin(tilt) * k + (1 - np.cos(tilt)) * (k @ k)
    return np.asarray(tilt_m @ rotation_z(rng.uniform(0, 2 * np.pi)))


def _under_and_over(
    mesh: RockMesh, cell: float
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Lowest and highest surface z of ``mesh`` on the grid columns it covers.

    Returns:
        bottom, top (per covered column) and the integer (ix, iy) grid index of each column, with
        the grid anchored at the world origin.

    """
    lo = np.floor(mesh.vertices[:, :2].min(axis=0) / cell).astype(np.int64)
    hi = np.ceil(mesh.vertices[:, :2].max(axis=0) / cell).astype(np.int64)
    ix, iy = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing='ij')
    idx = np.stack([ix.ravel(), iy.ravel()], axis=1)
    xy = idx * cell
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(mesh.faces, dtype=np.uint32)),
    )
    zmin = mesh.vertices[:, 2].min() - 1.0
    zmax = mesh.vertices[:, 2].max() + 1.0
    up = np.column_stack([xy, np.full(len(xy), zmin), np.zeros((len(xy), 2)), np.ones(len(xy))])
    down = np.column_stack([xy, np.full(len(xy), zmax), np.zeros((len(xy), 2)), -np.ones(len(xy))])
    rays = o3d.core.Tensor.from_numpy(
        np.ascontiguousarray(np.concatenate([up, down]), dtype=np.float32)
    )
    t = scene.cast_rays(rays, nthreads=1)['t_hit'].numpy()
    n = len(xy)
    hit = np.isfinite(t[:n]) & np.isfinite(t[n:])
    bottom = zmin + t[:n][hit]
    top = zmax - t[n:][hit]
    return bottom.astype(np.float64), top.astype(np.float64), idx[hit]


class _Heightfield:
    """Top surface of ground (z = 0) plus placed rocks on a square grid centred on the origin."""

    def __init__(self, half_extent: float, cell: float):
        self.cell = cell
        self.offset = int(np.ceil(half_extent / cell))
        self.z = np.zeros((2 * self.offset + 1, 2 * self.offset + 1))

    def rest_height(self, bottom: npt.NDArray[np.float64], idx: npt.NDArray[np.int64]) -> float:
        """Return the lift at which a shape with underside ``bottom`` over ``idx`` touches."""
        i = idx + self.offset
        return float(np.max(self.z[i[:, 0], i[:, 1]] - bottom))

    def inside(self, idx: npt.NDArray[np.int64]) -> bool:
        i = idx + self.offset
        return bool(np.all(i >= 0) and np.all(i < self.z.shape[0]))

    def add(self, top: npt.NDArray[np.float64], idx: npt.NDArray[np.int64]) -> None:
        i = idx + self.offset
        self.z[i[:, 0], i[:, 1]] = np.maximum(self.z[i[:, 0], i[:, 1]], top)


def _shapes(rng: np.random.Generator, cfg: PileConfig) -> list[str]:
    p_flat, p_long = cfg.flat_fraction, cfg.elongated_fraction
    if p_flat < 0 or p_long < 0 or p_flat + p_long > 1:
        raise StockpileError('flat and elongated fractions must be >= 0 and sum to at most 1')
    names = ['equant', 'flat', 'elongated']
    probs = [1 - p_flat - p_long, p_flat, p_long]
    return [names[int(i)] for i in rng.choice(3, size=cfg.rocks, p=probs)]


def _slide_inwards(
    field_: _Heightfield,
    bottom: npt.NDArray[np.float64],
    idx: npt.NDArray[np.int64],
    shift: npt.NDArray[np.int64],
    dz: float,
    climb: float = 0.002,
    max_steps: int = 400,
) -> tuple[float, npt.NDArray[np.int64]]:
    """Move a resting rock cell by cell towards the pile centre while it need not climb.

    A rock that lands apart rolls or is pushed into contact with its neighbours, as in a real heap;
    it stops where going on would lift it by more than ``climb`` [m].
    """
    for _ in range(max_steps):
        if not np.any(shift):
            break
        step = -np.sign(shift) * (np.abs(shift) >= np.abs(shift).max() / 2)
        new = shift + step
        new_dz = field_.rest_height(bottom, idx + new)
        if new_dz > dz + climb:
            break
        shift, dz = new, new_dz
    return dz, shift


def build_pile(rng: np.random.Generator, cfg: PileConfig, candidates: int = 24) -> list[PlacedRock]:
    """Generate and stack ``cfg.rocks`` rocks around the world origin on the ground z = 0.

    Args:
        rng: Random generator.
        cfg: Pile parameters.
        candidates: Drop points tried per rock; the lowest and most central resting place wins,
            then the rock slides towards the centre until it touches what is there.

    Raises:
        StockpileError: A rock found no resting place inside the settling grid.

    """
    if cfg.rocks < 1:
        raise StockpileError('a pile needs at least one rock')
    sizes = cfg.gradation.sample(rng, cfg.rocks)
    shapes = _shapes(rng, cfg)
    meshes = [
        random_rock(rng, float(b), s, cfg.roughness, cfg.subdivisions, cfg.rounding)
        for b, s in zip(sizes, shapes, strict=True)
    ]
    ab = [float(b) ** 2 * SHAPES[s][0] for b, s in zip(sizes, shapes, strict=True)]
    layer_radius = float(np.sqrt(sum(ab) / np.pi))
    sigma = cfg.spread * layer_radius
    half = 3 * layer_radius + 2 * float(sizes.max()) * 2.5
    field_ = _Heightfield(half, cfg.cell)
    placed: list[PlacedRock] = []
    for k, (mesh0, shape, b) in enumerate(zip(meshes, shapes, sizes, strict=True)):
        mesh = mesh0.transformed(_resting_rotation(rng), np.zeros(3))
        bottom, top, idx = _under_and_over(mesh, cfg.cell)
        aim = rng.normal(0.0, sigma, size=2)
        best: tuple[float, float, npt.NDArray[np.int64]] | None = None
        for _ in range(candidates):
            xy = aim + rng.normal(0.0, 0.5 * b, size=2)
            shift = np.round(xy / cfg.cell).astype(np.int64)
            if not field_.inside(idx + shift):
                continue
            dz = field_.rest_height(bottom, idx + shift)
            # Low and central wins: a rock settles into a hollow near the middle of the heap.
            score = dz + cfg.compactness * float(np.hypot(*xy))
            if best is None or score < best[0]:
                best = (score, dz, shift)
        if best is None:
            raise StockpileError(f'rock {k + 1} found no resting place; lower the pile spread')
        _, dz, shift = best
        dz, shift = _slide_inwards(field_, bottom, idx, shift, dz)
        field_.add(top + dz, idx + shift)
        moved = mesh.transformed(np.eye(3), [shift[0] * cfg.cell, shift[1] * cfg.cell, dz])
        placed.append(PlacedRock(id=k + 1, shape=shape, b_nominal=float(b), mesh=moved))
    return placed
