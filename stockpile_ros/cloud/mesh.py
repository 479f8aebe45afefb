"""A point cloud made into the metric z-up stockpile mesh and its ``mesh.json``.

The route: units to metres, isolated points dropped, levelled (:mod:`.level`), normals taken as
given or estimated from the nearest points and turned towards the sensor or, without one, to
where the cloud is seen from (:mod:`.orient`), then the screened
Poisson surface of :func:`~stockpile_ros.recon.surface.poisson_surface` (density trimming,
vertices far from every point dropped, cropped to the points' box) at a depth whose finest cell
is about the cloud's resolution: its point spacing, or a few times its noise where the points
scatter about their surface by more than a third of their spacing (:mod:`.noise`). Every length
here is in point spacings or resolutions, so a 1 cm survey of a gravel bar and a 2 mm scan of a
handful of pebbles are meshed alike, and a scan denser than its noise is meshed as its noise
allows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Annotated, Any, Literal

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from ..artefacts import MeshInfo, ScaleMethod, ScaleRecord, SimilarityRecord, to_json
from ..errors import CaptureError
from ..meshio import LabelledMesh
from ..ranges import Range
from ..recon.surface import PoissonOptions, poisson_surface
from ..segment.params import RESOLVABLE_EDGES, SegmentParams
from .level import SIGN_FROM_INPUT_Z, level_transform, parse_up, trend_up
from .noise import point_noise
from .orient import orient_outward
from .read import Cloud

__all__ = [
    'CloudOptions',
    'cloud_segment_params',
    'estimate_normals',
    'mesh_cloud',
    'one_per_cell',
    'point_spacing',
    'poisson_depth',
]

F64 = npt.NDArray[np.float64]

# Octree side over the points' longest side: open3d's Poisson default scale.
_POISSON_SCALE = 1.1
# Given normals count as oriented when this share of them agrees on a side of the surface.
_ORIENTED_SHARE = 0.8
# Queries enough to pin the median nearest-neighbour distance to a fraction of a percent.
_SPACING_SAMPLE = 100_000
# A surface crosses about two cells of a grid per cell area: one point kept per cell of 1.5
# spacings leaves a median nearest-neighbour distance near the spacing.
_THIN_CELL = 1.5
# Fewest points a surface can be meshed from.
_MIN_POINTS = 100
# Formats whose z is up by convention: survey coordinates, and a sensor's stream (REP 103).
_Z_UP_FORMATS = frozenset({'las', 'laz', 'pointcloud2'})


@dataclass(frozen=True)
class CloudOptions:
    """How a point cloud (a file, or a PointCloud2 stream) becomes the stockpile mesh.

    Attributes:
        source: What the reconstruction meshes: auto (the cloud when points arrived and no
            keyframes are held), images (Structure-from-Motion of the keyframes, as without a
            cloud) or cloud (the accumulated cloud even when keyframes are held).
        topic: PointCloud2 topic of a bag to replay ('' takes the one with most messages, the
            node set's own outputs left out).
        up: Up direction in the cloud's frame, x,y,z, or fit: the normal of the cloud's robust
            trend plane (every point, ground or no ground).
        ground_percentile: z = 0 is the trend plane moved down to this percentile of the heights
            [%]: the ground where some is bare, the bottom of the gaps between grains on a bed
            covered by them.
        neighbours: Nearest points a normal is estimated from (plane fit) [points].
        isolated_spacings: A point farther than this many median spacings from its nearest
            neighbour is not on the sampled surface and is dropped [spacings].
        noise_sigmas: The cloud's resolution, the length ``cell_spacings`` and
            ``min_rock_spacings`` count in, is its median point spacing, or this many standard
            deviations of its noise (the points' scatter along the surface's normal, see
            :func:`~.noise.point_noise`) where that is longer [noise standard deviations; 0: the
            spacing alone]. A cell finer than the noise allows draws the noise as bumps and
            creases, and a smallest rock of ten spacings is then cut from pieces of rocks: the
            simulated surveys on which 10 spacings measured as they should (1.5 cm, 1 cm and
            7.5 mm at 2 mm range noise: 3.0-4.7 noise lengths a spacing as read) hold 3 or
            more; a denser one is treated as one of 3. On bench/bench_cloud.py's 220-rock
            survey at 2.8 mm (1.2 M points, noise read as 1.9 mm: 0.68 of a spacing) the
            spacing alone reported 561-590 rocks for 220 from PLY, XYZ and LAZ (precision
            0.36-0.38, Poisson depth 11), 3 noise lengths 233-245 (recall 0.98, precision
            0.85-0.89, median b error 4.9-5.2 %, depth 10; 145-160 s from file to report against
            180-215 s); its 7.5 mm survey and the 1 cm gravel bar (3.0 and 3.7 noise lengths a
            spacing) came out as before.
        depth: Poisson octree depth; 0 chooses it from the resolution (see cell_spacings).
        cell_spacings: The finest Poisson cell is at most this many resolutions (see
            noise_sigmas) [resolutions: point spacings unless the noise is coarser]: one keeps
            every sample in a cell of its own.
        trim_spacings: The Poisson surface is kept where it lies within this many median point
            spacings of a point (in place of poisson.max_distance, a photo route's) [spacings].
            With the finest cell at a spacing, a vertex on a sampled surface lies within about
            0.7 spacings of a sample, plus the noise; the bridges Poisson draws over a scanner's
            occlusion shadows lie farther, and where they meet the rocks they leave creases that
            the search cuts rocks at. On the 220-rock survey of bench/bench_cloud.py (7.5 mm,
            2 mm noise), visible rocks found and precision: 4 spacings 0.65 and 0.28, 3: 0.75 and
            0.32, 2: 0.86 and 0.47, 1.5: 0.86 and 0.55, 1.25: 0.90 and 0.63, 1: 0.70 and 0.46
            (holes in the rocks). 1.5 keeps a margin from that edge for noisier scanners.
        max_depth: Deepest automatic Poisson depth (memory and time grow about fourfold a
            level); a warning says when it limits the cell.
        max_points: Points kept from a stream; past it the accumulated cloud is thinned on a
            voxel grid at its own spacing [points].
        max_rock_spacings: Where the smallest rock of interest is given (segment.min_rock_b,
            or a class to check), a cloud that samples it more finely than this many
            resolutions across is thinned to one point a cell of a grid before it is meshed,
            and meshed at that coarser resolution [resolutions across the smallest rock of
            interest; 0: never thinned]. A median edge of the mesh is 1.2-1.4 resolutions
            (measured on bench/bench_cloud.py's surveys), so 60 resolutions are 43-52 edges,
            at or above ``SHARP_EDGES`` (40), from which the segmentation finds what it should
            on bench/bench_yardstick.py's beds. On a bed of 80 rocks of b 0.4-1.2 m scanned
            at 5.5 mm (753k points; bench/bench_cloud.py, 2 mm noise, smallest rock given as
            0.5 m) thinning to 8.3 mm kept 362k points and took the run from file to report
            from 157 to 92-95 s, with 50 rocks reported for 48: of the 26 rocks of at least 0.5
            m at least 30 % visible 25 found for 24, precision 0.98 -> 1.00, median b error
            5.6 -> 5.9 %, D50 error -2.2 -> -1.3 %.
        min_rock_spacings: The smallest rock a cloud resolves, across [resolutions (see
            noise_sigmas): point spacings unless the noise is coarser]. Its
            Poisson mesh is segmented with segment.min_rock_edges set to this length in the
            mesh's median edges (about 1.5 spacings on a survey: Poisson keeps one to two samples
            a cell), unless segment.min_rock_edges is set explicitly. The floor of 20 edges is
            what a mesh reconstructed from photos resolves; a cloud's points resolve their
            spacing. On four simulated 1 cm surveys (sim/survey.py, seed 1; 30 rocks of 12-30 cm,
            24 of 14-30, 60 of 10-40, 100 of 8-25; 2 mm noise; surface trimmed at
            trim_spacings 1.5) 10 spacings found 100, 92, 94 and 86 % of the visible rocks at
            precisions 0.83, 0.67, 0.77 and 0.89 (the false ones mostly rocks split in two), 14
            spacings 93, 92, 87 and 59 % at 0.96, 0.81, 0.85 and 0.86 (the small rocks of the
            last pile merged, 22 merges against 11): a bed of small grains needs the lower.
            Trimmed at 4 spacings, as before trim_spacings, 10 spacings had found 93, 96, 86 and
            74 % at 0.59, 0.64, 0.64 and 0.74.

    """

    source: Literal['auto', 'images', 'cloud'] = 'auto'
    topic: str = ''
    up: str = 'fit'
    ground_percentile: Annotated[float, Range(0.0, 50.0)] = 1.0
    neighbours: Annotated[int, Range(5, 200)] = 20
    isolated_spacings: Annotated[float, Range(2.0, 1000.0)] = 10.0
    noise_sigmas: Annotated[float, Range(0.0, 100.0)] = 3.0
    depth: Annotated[int, Range(0, 14)] = 0
    cell_spacings: Annotated[float, Range(0.25, 16.0)] = 1.0
    trim_spacings: Annotated[float, Range(0.5, 1000.0)] = 1.5
    max_depth: Annotated[int, Range(5, 14)] = 11
    max_points: Annotated[int, Range(1000, 1_000_000_000)] = 5_000_000
    max_rock_spacings: Annotated[float, Range(0.0, 100_000.0)] = 60.0
    min_rock_spacings: Annotated[float, Range(4.0, 10_000.0)] = 10.0


def point_spacing(points: F64, seed: int = 0) -> tuple[float, F64]:
    """Median distance to the nearest other point, and every point's such distance.

    Repeated points count once: they would pull the spacing to nothing.
    """
    unique, inverse = np.unique(points, axis=0, return_inverse=True)
    if len(unique) < 2:
        return 0.0, np.zeros(len(points))
    dist, _ = cKDTree(unique).query(unique, k=2)
    nearest = np.asarray(dist[:, 1], dtype=np.float64)
    rng = np.random.default_rng(seed)
    sample = nearest if len(nearest) <= _SPACING_SAMPLE else rng.choice(nearest, _SPACING_SAMPLE)
    return float(np.median(sample)), np.asarray(nearest[np.ravel(inverse)])


def one_per_cell(points: F64, cell: float) -> npt.NDArray[np.int64]:
    """Return one point of each occupied cell of a grid of side ``cell``, by index.

    Each cell keeps its point nearest to the mean of the cell's points (ties to the lower index):
    the mean lies on the surface through them, where the cell's middle need not, and the points
    nearest the middles would pull the surface towards the grid (a plane 5 mm off the middle of
    cells of 5 cm, sampled with 2 mm of noise: kept 0.01 mm off it on average, against 0.89 mm
    by the middles). What is kept does not depend on the points' order beyond ties; indices
    ascending.
    """
    cells = np.floor(points / cell).astype(np.int64)
    _, inverse, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    inverse = np.ravel(inverse)
    off = np.zeros(len(points))
    for column in np.ascontiguousarray(points.T):
        mean = np.bincount(inverse, weights=column) / counts
        off += (column - mean[inverse]) ** 2
    order = np.lexsort((np.arange(len(points)), off, inverse))
    first = np.ones(len(order), dtype=bool)
    first[1:] = inverse[order[1:]] != inverse[order[:-1]]
    return np.sort(order[first])


def poisson_depth(extent: float, spacing: float, cell_spacings: float, max_depth: int) -> int:
    """Shallowest octree depth whose finest cell is at most ``cell_spacings`` times ``spacing``.

    Args:
        extent: Longest side of the points' bounding box.
        spacing: The cloud's resolution: its median point spacing, or a multiple of its noise
            (same units).
        cell_spacings: Finest cell in units of ``spacing``.
        max_depth: Deepest depth returned.

    """
    cells = _POISSON_SCALE * extent / (cell_spacings * spacing)
    return int(min(max_depth, max(1, math.ceil(math.log2(max(cells, 2.0))))))


def _orient(normals: F64, points: F64, viewpoints: F64 | None, spacing: float) -> tuple[F64, str]:
    """Turn each normal towards its sensor, or to the side the cloud is seen from without one."""
    if viewpoints is not None:
        away = np.einsum('ij,ij->i', normals, viewpoints - points) < 0
        return np.where(away[:, None], -normals, normals), 'towards its sensor'
    unit = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    turned, seen = orient_outward(points, unit, spacing)
    how = f'towards where it is seen from ({100 * seen:.0f} % seen, the rest as their neighbours)'
    return turned, how


def _normals(
    local: F64, given: F64 | None, viewpoints: F64 | None, neighbours: int, spacing: float
) -> tuple[F64, str]:
    """Return normals in the stockpile frame (``given``, already rotated, or estimated)."""
    if given is not None:
        up = float(np.mean(given[:, 2] > 0))
        if up >= _ORIENTED_SHARE:
            return given, 'given'
        if up <= 1 - _ORIENTED_SHARE:
            return -given, 'given, every one turned over (they faced down)'
        turned, how = _orient(given, local, viewpoints, spacing)
        return turned, f'given without a consistent side: each turned {how}'
    return estimate_normals(local, viewpoints, neighbours, spacing)


def estimate_normals(
    points: F64, viewpoints: F64 | None, neighbours: int, spacing: float
) -> tuple[F64, str]:
    """Plane-fit normals of ``points`` over their ``neighbours`` nearest, turned to be seen.

    Args:
        points: Nx3 points.
        viewpoints: Per point, where its sensor saw it from (each normal is turned towards it),
            or None: towards where the cloud is seen from (``orient_outward``).
        neighbours: Points in each plane fit.
        spacing: The points' spacing [m], for ``orient_outward``.

    Returns:
        Unit normals and how they were found, in words.

    """
    import open3d

    o3d: Any = open3d
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=neighbours))
    turned, how = _orient(np.asarray(pcd.normals, dtype=np.float64), points, viewpoints, spacing)
    return turned, f'estimated ({neighbours} points), {how}'


def mesh_cloud(
    cloud: Cloud,
    options: CloudOptions,
    poisson: PoissonOptions,
    metres_per_unit: float,
    scale_method: ScaleMethod,
    viewpoints: F64 | None = None,
    min_rock_b: float = 0.0,
) -> tuple[LabelledMesh, MeshInfo]:
    """Mesh a cloud into the ``stockpile`` frame.

    Args:
        cloud: Points in their own units and frame.
        options: Levelling, normals and depth.
        poisson: Trimming and threads of the Poisson solve (its depth is replaced by this one's
            choice unless ``options.depth`` is set).
        metres_per_unit: Metres per unit of the cloud (1 in model units).
        scale_method: ``scale.method`` of ``mesh.json``: ``input units``, ``given``, ``sensor``
            or ``none``.
        viewpoints: Nx3 sensor position of each point (same frame), to orient normals.
        min_rock_b: The smallest rock of interest asked for [m; 0: none], which a cloud need
            not sample more finely than ``options.max_rock_spacings`` across.

    Returns:
        The mesh (labels 0, colours when the cloud has some) and what it is (``mesh.json``).

    Raises:
        CaptureError: Too few points, all points at one place, or no surface left.

    """
    points = np.asarray(cloud.points, dtype=np.float64)
    warnings = list(cloud.warnings)
    if len(points) < _MIN_POINTS:
        raise CaptureError('mesh', f'{len(points)} points, at least {_MIN_POINTS} needed',
                           'Give a cloud that covers the pile')  # fmt: skip
    spacing, nearest = point_spacing(points)
    if spacing <= 0:
        raise CaptureError('mesh', 'every point lies at one place', 'Give a cloud of the pile')
    keep = nearest <= options.isolated_spacings * spacing
    if not keep.all():
        warnings.append(
            f'{int((~keep).sum())} isolated points dropped (farther than '
            f'{options.isolated_spacings:g} spacings from any other)'
        )
    use = np.flatnonzero(keep)
    points = points[use]
    given = None if cloud.normals is None else cloud.normals[use]
    up = parse_up(options.up)
    up_method = 'given (cloud.up)'
    if up is None:
        up, why = trend_up(points, given)
        up_method = f'robust trend plane of every point; its sign: {why}'
        if why == SIGN_FROM_INPUT_Z and cloud.format not in _Z_UP_FORMATS:
            warnings.append(
                "which side is up was taken from the input's +z: no normals were given, the "
                'surface rises clear of its trend plane to neither side only (no bare ground) '
                'and bulges clearly to neither (a noisy cloud). If the input has z down (NED, a '
                'camera frame), the pile was measured upside down: pass --up X,Y,Z'
            )
    tilt = math.degrees(math.acos(min(1.0, abs(float(up[2])))))
    sim, plane = level_transform(points, up, metres_per_unit, options.ground_percentile)
    local = sim.apply(points)
    spacing_m = spacing * metres_per_unit
    noise_m = point_noise(local)
    resolution = max(spacing_m, options.noise_sigmas * noise_m)
    thinned_to = 0.0
    if min_rock_b > 0 and options.max_rock_spacings > 0:
        thinned_to = min_rock_b / options.max_rock_spacings
    if thinned_to > resolution:
        # The noise was read on every point: thinning leaves the sensor's scatter as it was.
        kept = one_per_cell(local, _THIN_CELL * thinned_to)
        use, local = use[kept], local[kept]
        given = None if given is None else given[kept]
        resolution = thinned_to
    else:
        thinned_to = 0.0
        if resolution > spacing_m:
            warnings.append(
                f'the points scatter {noise_m:.2g} m about their surface, '
                f'{noise_m / spacing_m:.2g} of their spacing: meshed and cut as a cloud of '
                f'{resolution:.2g} m ({options.noise_sigmas:g} noise standard deviations, '
                'cloud.noise_sigmas), as finer its noise would be drawn as creases that cut rocks'
            )
    rotated = None if given is None else given @ sim.rotation.T
    local_views = None
    if viewpoints is not None:
        local_views = sim.apply(np.asarray(viewpoints, dtype=np.float64)[use])
    normals, normal_method = _normals(local, rotated, local_views, options.neighbours, spacing_m)
    extent = float(np.max(local.max(axis=0) - local.min(axis=0)))
    depth = options.depth or poisson_depth(extent, resolution, options.cell_spacings,
                                           options.max_depth)  # fmt: skip
    cell = _POISSON_SCALE * extent / 2**depth
    if not options.depth and cell > options.cell_spacings * resolution * (1 + 1e-9):
        warnings.append(
            f'Poisson depth held at cloud.max_depth {depth}: its finest cell is '
            f'{cell / resolution:.2g} resolutions, coarser than the points resolve'
        )
    colors = None if cloud.colors is None else cloud.colors[use].astype(np.float64) / 255.0
    trimmed = replace(poisson, depth=depth, max_distance=options.trim_spacings)
    mesh, record = poisson_surface(local, normals, colors, trimmed)
    faces = np.asarray(mesh.triangles, dtype=np.int64)
    if len(faces) == 0:
        raise CaptureError(
            'mesh',
            'the Poisson surface of the cloud is empty after trimming',
            'Check that the cloud samples a surface (not a few scattered points)',
        )
    vcol = np.asarray(mesh.vertex_colors)
    out = LabelledMesh(
        vertices=np.asarray(mesh.vertices, dtype=np.float64),
        faces=faces,
        labels=np.zeros(len(faces), dtype=np.int32),
        colors=np.clip(np.round(vcol * 255), 0, 255).astype(np.uint8) if len(vcol) else None,
    )
    record.update({'depth_rule': 'given (cloud.depth)' if options.depth else
                   f'finest cell at most {options.cell_spacings:g} resolutions',
                   'finest_cell': cell, 'points': len(local)})  # fmt: skip
    metric = scale_method != 'none'
    edges = np.linalg.norm(out.vertices[faces] - out.vertices[np.roll(faces, 1, axis=1)], axis=2)
    edge = float(np.median(edges))
    min_rock_edges = max(RESOLVABLE_EDGES, options.min_rock_spacings * resolution / edge)
    note = '' if metric else 'no unit given for the coordinates: model units'
    info = MeshInfo(
        scale=ScaleRecord(scale_method, metres_per_unit, None, {}, note),
        units='m' if metric else 'model',
        ground_plane_model=[float(v) for v in plane],
        model_to_stockpile=SimilarityRecord.of(sim),
        poisson=to_json(record),
        cloud={
            'source': cloud.source,
            'format': cloud.format,
            'points_read': len(cloud.points),
            'points_used': len(local),
            'spacing': spacing_m,
            'noise': noise_m,
            'resolution': resolution,
            'thinned_to': thinned_to,
            'normals': normal_method,
            'up': {'method': up_method, 'vector': [float(v) for v in up], 'tilt_deg': tilt},
            'ground_percentile': options.ground_percentile,
            'median_edge': edge,
            'min_rock_edges': min_rock_edges,
            'min_rock_rule': f'{options.min_rock_spacings:g} resolutions (cloud.min_rock_spacings)',
            'warnings': warnings,
        },
    )
    return out, info


def cloud_segment_params(
    params: SegmentParams, info: MeshInfo | None, explicit: frozenset[str]
) -> SegmentParams:
    """Return ``params`` with the smallest rock a cloud's mesh resolves (``mesh.json``'s ``cloud``).

    A mesh made from photos (no ``cloud`` record) or a ``segment.min_rock_edges`` set explicitly
    keeps ``params`` as they are.
    """
    cloud = None if info is None else info.cloud
    if cloud is None or 'segment.min_rock_edges' in explicit:
        return params
    return replace(params, min_rock_edges=float(cloud['min_rock_edges']))
