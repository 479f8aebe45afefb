"""From a stockpile mesh to the report: segment, measure every rock, grade the pile."""

from __future__ import annotations

import copy
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial import ConvexHull, QhullError
from scipy.spatial.transform import Rotation

from ..artefacts import MeshInfo
from ..result import (
    FloorTry,
    GradationRecord,
    MeasureRecord,
    MeshRecord,
    Report,
    RockRecord,
    SegmentationRecord,
)
from .gradation import gradation
from .measure import (
    MeasureParams,
    RockMeasure,
    measure_rocks,
    sheet_warnings,
    solid_axes,
    split_sheets,
    visibility_warnings,
)
from .params import (
    RESOLVABLE_EDGES,
    SHARP_EDGES,
    RockScale,
    SegmentParams,
    median_edge,
    rock_scale,
)
from .qa import ReportOptions, bootstrap_intervals, decide, refuse, rosin_rammler, sieve_table
from .segmentation import Segmentation, segment_mesh

__all__ = [
    'FLOOR_STEPS',
    'TRUNCATED_MIN_ROCKS',
    'TRUNCATED_RATIO',
    'TWO_SIZES_MIN_ROCKS',
    'Analysis',
    'Measured',
    'analyse_mesh',
    'floor_warnings',
    'grade',
    'kept_floor',
    'principal_axes',
    'segment_and_measure',
    'settle_floor',
    'truncation_warnings',
]

#: Fewest rocks in the band just above the mesh's smallest resolved rock for
#: ``truncation_warnings`` to read the pile's sizes as cut there (fewer is chance).
TRUNCATED_MIN_ROCKS = 5

#: How many times the rocks of any other band ``truncation_warnings`` asks of the band just
#: above the floor: between the 2.8 of a pile spread evenly by mass in log size (2.5-3.7 on
#: bench/bench_yardstick.py's beds with the floor at their smallest b) and the 1 or less of
#: pieces above a floor under the pile's smallest rocks.
TRUNCATED_RATIO = 2.0

#: Fewest rocks in each of the two fullest bands, the one near the floor and the one above the
#: gap, for ``truncation_warnings`` to read a gap between them as two kinds of rock (a band's
#: count varies by about its square root from draw to draw, so a gap under ten says little).
TWO_SIZES_MIN_ROCKS = 10

#: Floors :func:`settle_floor` tries under ``SegmentParams.min_rock_edges``, each a band of
#: ``truncation_warnings`` (a factor sqrt 2) under the last: from the default 20 edge lengths
#: down to 7.1, about the floor a cloud is segmented at (``cloud.min_rock_spacings`` point
#: spacings: 7.3 edge lengths on bench/bench_cloud.py's gravel bar).
FLOOR_STEPS = 3


@dataclass(frozen=True)
class Analysis:
    """Everything one run produced.

    Attributes:
        vertices: Nx3 mesh vertices [m] in ``report.frame_id``.
        faces: Mx3 triangles.
        colors: Nx3 uint8 vertex colours, or None.
        segmentation: Labels and what they came from.
        rocks: Measured rocks (ids as in ``segmentation.labels``).
        report: The report (``report.json``, docs/formats.md).

    """

    vertices: npt.NDArray[np.float64]
    faces: npt.NDArray[np.int64]
    colors: npt.NDArray[np.uint8] | None
    segmentation: Segmentation
    rocks: list[RockMeasure]
    report: Report


def _reconstruction_warnings(info: MeshInfo) -> list[str]:
    """Return what ``mesh.json`` says went wrong upstream, in words for report.json."""
    out = []
    off = info.keyframes_off_path
    if off:
        out.append(
            f'{len(off)} keyframes were left out: Structure-from-Motion placed them far from '
            f'where odometry puts the camera (repeating texture?): {", ".join(off)}.'
        )
    rejected = info.scale_details.get('odometry', {}).get('rejected')
    if rejected:
        out.append(f'Odometry was not used for the scale: {rejected}.')
    # What reading and meshing a point cloud dropped or guessed (stockpile_ros.cloud).
    out += list((info.cloud or {}).get('warnings', []))
    return out


def principal_axes(
    vertices: npt.NDArray[np.float64], seg: Segmentation, rock_ids: list[int]
) -> dict[int, list[float]]:
    """Orientation of each rock's principal axes as a quaternion ``[x, y, z, w]``.

    The axes are those the measurement takes a, b, c along (:func:`~.measure.solid_axes` of the
    convex hull of the rock's visible surface): the rotation takes x to the a axis, y to b and z
    to c (right-handed, c flipped where needed).
    """
    out: dict[int, list[float]] = {}
    order = np.argsort(seg.labels, kind='stable')
    bounds = np.searchsorted(seg.labels[order], np.arange(int(seg.labels.max(initial=0)) + 2))
    for rock in rock_ids:
        tri = seg.faces[order[bounds[rock] : bounds[rock + 1]]]
        try:
            _, axes, _ = solid_axes(ConvexHull(vertices[np.unique(tri)]))
        except (QhullError, ValueError):
            continue
        if np.linalg.det(axes) < 0:
            axes = axes * np.array([1.0, 1.0, -1.0])
        out[rock] = [float(q) for q in Rotation.from_matrix(axes).as_quat()]
    return out


def _resolution_warnings(seg: Segmentation) -> list[str]:
    """Return a warning when the smallest rock of interest asked for is finer than the mesh.

    Under ``min_rock_edges`` the mesh does not resolve it; under ``SHARP_EDGES`` it does, but
    rocks are joined to their neighbours more often than a check should accept.
    """
    scale = seg.scale
    if scale.requested < scale.min_rock_b:
        return [
            f'The smallest rock of interest ({scale.source}) has b = {scale.requested:.3f} m, '
            f'under the {seg.params.min_rock_edges:g} median edge lengths '
            f'({scale.min_rock_b:.3f} m) the mesh resolves: rocks under that size may be joined '
            'to a neighbour. Capture the pile closer, or reconstruct it finer.'
        ]
    across = scale.requested / scale.edge if scale.edge > 0 else float('inf')
    if scale.source == 'mesh' or across >= SHARP_EDGES:
        return []
    return [
        f'The smallest rock of interest ({scale.source}) has b = {scale.requested:.3f} m, '
        f'{across:.0f} median edge lengths of the mesh: on simulated beds of 300 angular rocks, '
        f'recall was 0.81-0.89 at 20 edge lengths, 0.85-0.94 at 30 and 0.93-0.96 at '
        f'{SHARP_EDGES:g}, the lost rocks joined to a neighbour. For a check, capture the '
        'pile closer or reconstruct it finer, to edges of '
        f'{scale.requested / SHARP_EDGES:.3g} m or less.'
    ]


def truncation_warnings(scale: RockScale, sizes: Sequence[float], units: str) -> list[str]:
    """Return a warning when the pile's sizes do not fall off towards the smallest rock resolved.

    With no smallest rock of interest given (by ``min_rock_b`` or a class), the mesh's floor
    (``min_rock_edges`` median edge lengths, ``b0``) sets what is a rock: smaller ones are joined
    to a neighbour or left out, silently. A pile holds more rocks the smaller they are (one
    spread evenly by mass in log size about eight times more per halving of b), so where
    the floor cuts into its sizes the band ``[b0, sqrt 2 b0)`` holds the most rocks of any band of
    that width, about 2.8 times the next; where the pile's smallest rocks lie above the floor it
    holds pieces of larger rocks and partly seen ones (on the README's reconstructed piles 2-4
    rocks, no more than the fullest band of true rocks; on a cloud far denser than its rocks need,
    hundreds: the warning names both causes). The warning comes when it holds
    ``TRUNCATED_RATIO`` times as many as any other band, and ``TRUNCATED_MIN_ROCKS`` or more: the
    pile's gradation is then that of its rocks from about ``b0`` up.

    Where instead the sizes fall from a group near the floor to a gap and rise again to a fuller
    group above it (``_size_gap``), the warning says so: a pile's rocks grow fewer with size
    from its smallest up, and a group near the floor apart from the rest is most likely pieces of
    the larger rocks (on bench/bench_cloud.py's riprap bed, 100 rocks of b 0.3-0.8 m scanned at
    7 mm, with the normals of 2026-12-06 the reported sizes in bands from the floor of 6.9 cm ran
    36, 29, 11, 20, 45, 12, 5, and 61 of the 158 rocks reported were pieces of rocks found; with
    those turned as now 21-24, 15-16, 13-14, 22-25, 37-39, 13-15, 5-6 and 30 of the 129 from
    the PLY, warned of on two of the three files; its gravel bars and piles fall off or rise
    steadily), or else a gap-graded pile. It names where the fuller group begins: given as the
    smallest rock there (0.196 m), the 7 mm scan reported 89 rocks, 5 of them false (the normals
    of 2026-12-06).

    Args:
        scale: The segmentation's scale (``Segmentation.scale``).
        sizes: The b of every rock measured, in the units of ``scale``.
        units: Their name, for the message.

    Returns:
        The warning, or nothing.

    """
    b0 = scale.min_rock_b
    if scale.source != 'mesh' or b0 <= 0 or scale.edge <= 0:
        return []
    b = np.asarray(sizes, dtype=np.float64)
    counts = _bands(b, b0)
    resolves = (
        f'{b0:.3g} {units}, the smallest rock this mesh resolves '
        f'({b0 / scale.edge:.0f} median edge lengths)'
    )
    low, other = int(counts[0]), int(counts[1:].max(initial=0))
    if _piled_up(counts):
        return [
            f'{low} of {len(b)} rocks measure b under {np.sqrt(2.0) * b0:.3g} {units}, against at '
            f'most {other} in any other band of sizes a factor 1.41 wide: '
            f'the sizes do not fall off towards {resolves}: either the pile holds smaller '
            'rocks, joined to neighbours or left out, and its gradation is that of the rocks from '
            'about that size up, or the mesh is so much finer than the rocks that pieces of larger '
            'rocks count as rocks of that size (a dense cloud). Give the smallest rock that '
            'matters (segment.min_rock_b, or a class to check); to count smaller ones, capture '
            'the pile closer or reconstruct it finer.'
        ]
    gap = _size_gap(counts)
    if gap is None:
        return []
    near, at, far = gap
    between = np.sqrt(2.0) ** np.array([at, at + 1]) * b0
    return [
        f'The sizes come in two groups: {int(counts[:at].sum())} of {len(b)} rocks measure b '
        f'under {between[0]:.3g} {units}, near {resolves}, and {int(counts[at + 1 :].sum())} '
        f'from {between[1]:.3g} {units} up, with {int(counts[at])} between ({int(counts[near])} '
        f'and {int(counts[far])} in the fullest band of each group, bands a factor 1.41 wide). '
        'Rocks near the smallest resolved with few a little larger are most likely pieces of '
        'the larger rocks, cut along their own dents or where their surface was drawn facing '
        'the wrong way (a cloud far finer than its rocks: on a simulated riprap bed of rocks of '
        'b 0.3-0.8 m scanned at 7 mm, 30 of the 129 rocks reported), or else the pile holds two '
        'separate sizes; its gradation mixes them. Give the smallest rock that matters '
        f'(segment.min_rock_b: {between[1]:.3g} {units}, where the larger group begins, if the '
        'smaller are pieces of them; or a class to check).'
    ]


def _piled_up(counts: npt.NDArray[np.int64]) -> bool:
    """Whether the band just above the floor holds the most rocks by far (see the warning)."""
    low = int(counts[0])
    return low >= TRUNCATED_MIN_ROCKS and low >= TRUNCATED_RATIO * int(counts[1:].max(initial=0))


def _bands(b: npt.NDArray[np.float64], b0: float) -> npt.NDArray[np.int64]:
    """Count sizes in bands a factor sqrt 2 wide from ``b0`` up, the first with those under it."""
    band = np.floor(2.0 * np.log2(np.maximum(b, b0) / b0)).astype(np.int64)
    return np.bincount(band, minlength=1)


def _size_gap(counts: npt.NDArray[np.int64]) -> tuple[int, int, int] | None:
    """Find a gap between rocks near the floor and a fuller group above it.

    Returns:
        The fullest band under the gap (one of the two nearest the floor), the gap's band and the
        fullest band above it, where each of the two holds ``TWO_SIZES_MIN_ROCKS`` or more and
        the gap holds fewer than the smaller of them by over twice that count's square root (its
        spread from draw to draw), else None.

    """
    for at in range(1, len(counts) - 1):
        near = int(np.argmax(counts[: min(at, 2)]))
        far = at + 1 + int(np.argmax(counts[at + 1 :]))
        fewer = min(int(counts[near]), int(counts[far]))
        if fewer >= TWO_SIZES_MIN_ROCKS and counts[at] < fewer - 2.0 * np.sqrt(fewer):
            return near, at, far
    return None


def grade(
    rocks: list[RockMeasure],
    spec: dict[str, Any] | None,
    rel_scale_uncertainty: float | None,
    options: ReportOptions,
    metric: bool,
    *,
    resolved_b: float,
) -> GradationRecord:
    """Grade measured rocks: the curve of b by mass, its intervals, the verdict, fit and sieves.

    Args:
        rocks: The rocks.
        spec: A class of the class table to check, or None.
        rel_scale_uncertainty: The scale's relative uncertainty (widens the intervals).
        options: Intervals (resamples, confidence, seed), the fit and the sieves' unit.
        metric: Whether sizes are metres: without a scale no class is checked (REFUSED), no
            mass is totalled and no sieve is read.
        resolved_b: b of the smallest rock the segmentation kept [m]: the class's limits under
            it are left undecided (see :func:`decide`).

    """
    sizes, masses = [r.b for r in rocks], [r.mass for r in rocks]
    curve = gradation(sizes, masses, 'b')
    intervals = bootstrap_intervals(sizes, masses, rel_scale_uncertainty, options)
    return GradationRecord(
        **{**asdict(curve), 'total_mass': curve.total_mass if metric else None},
        spec=decide(curve, spec, intervals, resolved_b) if metric else refuse(spec),
        intervals=intervals,
        rosin_rammler=rosin_rammler(curve) if options.rosin_rammler else None,
        sieves=sieve_table(curve, options.length_unit) if metric else [],
    )


def _rock_record(rock: RockMeasure, orientation_xyzw: list[float], metric: bool) -> RockRecord:
    return RockRecord(
        id=rock.id,
        centroid=list(rock.centroid),
        orientation_xyzw=orientation_xyzw,
        a=rock.a,
        b=rock.b,
        c=rock.c,
        esd=rock.esd,
        volume=rock.volume,
        # Without scale a mass would be model units cubed times a density: no kilograms.
        mass=rock.mass if metric else None,
        visible_area=rock.visible_area,
        visible_fraction=rock.visible_fraction,
        fer=rock.fer,
        sphericity=rock.sphericity,
        confidence=rock.confidence,
    )


@dataclass(frozen=True)
class Measured:
    """What :func:`segment_and_measure` found.

    Attributes:
        segmentation: The segmentation, the faces of the regions left out relabelled 0 (ground).
        rocks: The measured rocks.
        sheets: Regions left out as too thin (``MeasureParams.min_thickness``).

    """

    segmentation: Segmentation
    rocks: list[RockMeasure]
    sheets: list[RockMeasure]


def segment_and_measure(
    vertices: npt.NDArray[np.float64],
    faces: npt.NDArray[np.int64],
    seg_params: SegmentParams,
    measure_params: MeasureParams,
    spec: dict[str, Any] | None = None,
    on_step: Callable[[str, npt.NDArray[np.int32]], None] | None = None,
) -> Measured:
    """Segment a mesh (stockpile frame) and measure its rocks, sheets left out.

    ``on_step`` is :func:`segment_mesh`'s.
    """
    seg = segment_mesh(vertices, faces, seg_params, spec, on_step)
    rocks, sheets = split_sheets(measure_rocks(vertices, seg, measure_params), measure_params)
    if sheets:
        # Not rocks: their faces go with the ground, in the segmented mesh too.
        gone = np.isin(seg.labels, [r.id for r in sheets])
        seg = replace(seg, labels=np.where(gone, 0, seg.labels).astype(seg.labels.dtype))
    return Measured(seg, rocks, sheets)


def settle_floor(
    vertices: npt.NDArray[np.float64],
    faces: npt.NDArray[np.int64],
    seg_params: SegmentParams,
    measure_params: MeasureParams,
    spec: dict[str, Any] | None = None,
) -> tuple[Measured, list[FloorTry]]:
    """Segment and measure with the floor lowered to where the pile's smallest rocks are.

    For a mesh nothing vouches for (another tool's, with no ``mesh.json``), the floor
    ``min_rock_edges`` is a guess: fitted on meshes from photos, whose noise cuts rocks into
    pieces up to about its size, it sets the smallest rock of a mesh that is clean at the scale
    of its edges (a scanner cloud's Poisson mesh) far above the pile's smallest rocks, and the
    sizes then pile up against it (``truncation_warnings``). Where the floor sets the smallest
    rock of interest (none is asked for, or one under the floor) and they do, it is lowered a
    band of that test (a factor sqrt 2) at a time, ``FLOOR_STEPS`` times at most and never under
    the rock asked for, until they fall off towards it. A pile holds more rocks band after band
    towards its smallest (2.8 times more per band when spread evenly by mass in log size), so a
    floor under them finds its lowest band fuller than the next; where that band holds fewer,
    the rise ended above it, what it adds are pieces of rocks cut along the mesh's noise, and
    the floor above is kept. Where the sizes pile up at every floor tried (the pile holds rocks
    smaller still, or the noise cuts pieces of about each floor's size), the first is kept,
    unless the last is the smallest rock asked for (see :func:`kept_floor`).

    Measured (README, 2026-12-08): bench/bench_cloud.py's gravel bar (rocks of b 0.1-0.4 m)
    meshed at 11.5 mm and given as a mesh piles up at 20, 14.1 and 10 edge lengths and falls
    off at 7.1 with 109 rocks in its lowest band and 82 in the next: recall 0.32 -> 0.95, D50
    error +19.6 -> -0.0 %. bench/bench_yardstick.py's cobble bed with the noise of a mesh from
    photos, its smallest rock 19 edge lengths across, piles up at 20 and falls off at 14.1 with
    62 against 102 (precision 0.89 at 20, 0.80 at 14.1): 20 is kept. The reconstructed piles'
    meshes from photos fall off at 20.

    Returns:
        What was measured at the floor kept, and each floor tried in order (none where the
        smallest rock asked for is at or above the floor: the floor does not set it then).

    """
    edge = median_edge(vertices, faces)
    first = rock_scale(seg_params, edge, spec)
    if (first.source != 'mesh' and first.requested >= first.min_rock_b) or edge <= 0:
        return segment_and_measure(vertices, faces, seg_params, measure_params, spec), []
    # Under the smallest rock asked for, the floor no longer sets anything: the last floor tried.
    asked = 0.0 if first.source == 'mesh' else first.requested / edge
    steps = seg_params.min_rock_edges / np.sqrt(2.0) ** np.arange(FLOOR_STEPS + 1)
    floors = np.unique(np.maximum(steps[steps >= RESOLVABLE_EDGES], asked))[::-1]
    runs: list[Measured] = []
    tried: list[FloorTry] = []
    for edges in floors:
        measured = segment_and_measure(
            vertices, faces, replace(seg_params, min_rock_edges=float(edges)), measure_params, spec
        )
        scale = measured.segmentation.scale
        bands = _bands(np.array([r.b for r in measured.rocks]), scale.min_rock_b)
        # Whether they pile up against it, whether the floor or a smallest rock asked set it.
        cut = _piled_up(bands) or _size_gap(bands) is not None
        runs.append(measured)
        at_asked = scale.source != 'mesh' and scale.min_rock_b <= scale.requested
        b0 = float(scale.min_rock_b)
        tried.append(FloorTry(float(edges), b0, [int(n) for n in bands], cut, asked=at_asked))
        if not cut:
            break
    keep = kept_floor(tried)
    tried[keep] = replace(tried[keep], kept=True)
    return runs[keep], tried


def kept_floor(tried: Sequence[FloorTry]) -> int:
    """Return which of the floors :func:`settle_floor` tried, highest first, it keeps.

    The last, where the sizes fall off towards it and its lowest band is the fullest (or it is
    the first), or where it is the smallest rock asked for and they pile up against it (the
    pile holds smaller rocks, not counted as asked); the one above it where that band holds
    fewer than the next; the first where the sizes pile up against every floor tried.
    """
    last = tried[-1]
    if last.cut:
        return len(tried) - 1 if last.asked else 0
    if len(tried) == 1 or len(last.bands) < 2 or last.bands[0] >= last.bands[1]:
        return len(tried) - 1
    return len(tried) - 2


def floor_warnings(tried: Sequence[FloorTry], units: str) -> list[str]:
    """Say how :func:`settle_floor` set the smallest rock of a mesh nothing vouches for.

    Args:
        tried: The floors tried (:func:`settle_floor`).
        units: The mesh's units, for the message.

    Returns:
        A warning where floors under the first were tried; nothing where none was searched or
        the sizes fell off towards the first.

    """
    if len(tried) <= 1:
        return []
    (kept,) = [t for t in tried if t.kept]
    seen = '; '.join(
        f'{t.edges:.3g}: {", ".join(str(n) for n in t.bands[:2])} of {sum(t.bands)}' for t in tried
    )
    head = (
        'Floors tried for the smallest rock this mesh resolves (segment.min_rock_edges, median '
        f'edge lengths: rocks in the two bands a factor 1.41 wide above it, of all): {seen}. '
        f'Kept {kept.edges:.3g} ({kept.min_rock_b:.3g} {units}): '
    )
    first = tried[0].edges
    if kept is tried[-1]:
        reached = (
            'it is the smallest rock asked for'
            if kept.asked
            else "they fall off towards this one, its lowest band the fullest as a pile's "
            'smallest rocks make it'
        )
        why = (
            f'the sizes piled up against the higher floors and {reached}. That reads the mesh as '
            "clean at the scale of its edges, as a Poisson mesh of a scanner's cloud is; for a "
            'mesh made from photos, whose noise cuts rocks into pieces, set '
            f'segment.min_rock_edges={first:g}.'
        )
    elif not tried[-1].cut:
        why = (
            'a band lower the sizes fall off, but that band holds fewer rocks than the next, '
            "where a pile's count rises towards its smallest rocks: those are about this floor "
            "and what a lower one adds are pieces of rocks cut along the mesh's noise. Rocks "
            'under it, if the pile holds any, are not counted.'
        )
    else:
        why = (
            'the sizes piled up against every floor: the pile holds rocks smaller still, or the '
            "mesh's noise cuts rocks into pieces of about each floor's size. Its gradation is "
            'that of the rocks from about this size up. Give the smallest rock that matters '
            "(segment.min_rock_b), or the cloud the mesh was made from if it is a scanner's."
        )
    return [head + why]


def analyse_mesh(
    vertices: npt.ArrayLike,
    faces: npt.ArrayLike,
    colors: npt.NDArray[np.uint8] | None = None,
    *,
    seg_params: SegmentParams | None = None,
    measure_params: MeasureParams | None = None,
    spec: dict[str, Any] | None = None,
    mesh_info: MeshInfo | None = None,
    source: str = '',
    report_options: ReportOptions | None = None,
    search_floor: bool = False,
) -> Analysis:
    """Segment a stockpile mesh, measure its rocks and grade the pile.

    Args:
        vertices: Nx3 vertices, metric, stockpile frame (z up, ground at z = 0).
        faces: Mx3 triangles.
        colors: Optional vertex colours, kept for the segmented mesh.
        seg_params: Segmentation parameters (``default`` preset if None).
        measure_params: Measurement parameters (defaults if None).
        spec: A class of the class table to check the gradation against, or None.
        mesh_info: What the reconstruction says of the mesh (scale, keyframes, frame); None:
            model units.
        source: Where the mesh came from, recorded in the report.
        report_options: Intervals (resamples, confidence, seed) and the Rosin-Rammler fit.
        search_floor: Lower the floor ``min_rock_edges`` while the sizes pile up against it
            (:func:`settle_floor`): for a mesh nothing vouches for, another tool's.

    Returns:
        The analysis, report included.

    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    sp = seg_params or SegmentParams()
    mp = measure_params or MeasureParams()
    opts = report_options or ReportOptions()
    info = mesh_info or MeshInfo()
    metric = info.scale.metric
    t0 = time.perf_counter()
    # A class's sizes are metres: in model units they would set a meaningless smallest rock.
    checked = spec if metric else None
    floors: list[FloorTry] = []
    if search_floor:
        measured, floors = settle_floor(v, f, sp, mp, checked)
    else:
        measured = segment_and_measure(v, f, sp, mp, checked)
    t1 = time.perf_counter()
    seg, rocks = measured.segmentation, measured.rocks
    units = 'm' if metric else 'model units'
    orientation = principal_axes(v, seg, [r.id for r in rocks])
    identity = [0.0, 0.0, 0.0, 1.0]
    report = Report(
        frame_id=info.frame_id,
        units='m' if metric else 'model',
        scale=copy.deepcopy(info.scale),
        keyframes=copy.deepcopy(info.keyframes),
        rocks=[_rock_record(r, orientation.get(r.id, identity), metric) for r in rocks],
        gradation=grade(
            rocks, spec, info.scale.rel_uncertainty, opts, metric, resolved_b=seg.scale.min_rock_b
        ),
        segmentation=SegmentationRecord(
            **asdict(seg.params),
            scale=seg.scale,
            raw_regions=seg.raw_regions,
            segments=int(seg.labels.max()) if len(seg.labels) else 0,
            rocks_measured=len(rocks),
            seconds=round(t1 - t0, 3),
            measure=MeasureRecord(**asdict(mp)),
            floors=floors,
        ),
        mesh=MeshRecord(faces=len(f), vertices=len(v), source=source),
        warnings=_reconstruction_warnings(info)
        + _resolution_warnings(seg)
        + sheet_warnings(
            measured.sheets, mp, units, seg.params.ground_window_b * seg.scale.max_rock_b > 0
        )
        + visibility_warnings(rocks)
        + truncation_warnings(seg.scale, [r.b for r in rocks], units)
        + floor_warnings(floors, units),
    )
    return Analysis(v, f, colors, seg, rocks, report)
