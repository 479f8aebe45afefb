"""What the segment stage writes: ``result/report.json`` as one typed record and its parts.

The segment row of the stage table in :mod:`stockpile_ros.artefacts`: :class:`Report` is the
whole file, written with :func:`~stockpile_ros.artefacts.save` and read back with
:func:`~stockpile_ros.artefacts.load` (the same converter as the other stage records, the schema
checked). Its parts: one :class:`RockRecord` per rock, the pile's :class:`GradationRecord` (the
curve of :class:`GradationCurve` with its :class:`Intervals`, the :class:`ClassDecision` against a
class and its :class:`LimitRow` per limit, the :class:`RosinRammler` fit, the :class:`Sieve`
table), the :class:`SegmentationRecord` (the parameters used, the lengths they scaled with, what
came of them), the :class:`MeshRecord` and, once the result folder is written, the
:class:`ProvenanceRecord`. ``docs/formats.md`` says what every field means.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

from .artefacts import ArtefactError, KeyframePose, ScaleMethod, ScaleRecord, SimilarityRecord
from .meshcheck import MeshCheck
from .segment.measure import MeasureParams
from .segment.params import RockScale, SegmentParams
from .segment.provenance import Provenance

__all__ = [
    'Basis',
    'ClassDecision',
    'FloorTry',
    'GradationCurve',
    'GradationRecord',
    'Intervals',
    'LimitRow',
    'LimitStatus',
    'MeasureRecord',
    'MeshRecord',
    'ProvenanceRecord',
    'ProvenanceScale',
    'Report',
    'RockRecord',
    'RosinRammler',
    'SegmentationRecord',
    'Sieve',
    'Verdict',
]

Basis = Literal['mass', 'count']
Verdict = Literal['PASS', 'FAIL', 'UNDECIDED', 'NOT CHECKED', 'REFUSED']
LimitStatus = Literal['pass', 'fail', 'undecided']


@dataclass
class RockRecord:
    """One rock of ``report.json`` (:class:`~.segment.measure.RockMeasure` and its orientation).

    Attributes:
        id: Rock id, as in ``segments.ply``.
        centroid: Centroid of the completed shape [m].
        orientation_xyzw: Rotates x onto the rock's a axis, y onto b and z onto c.
        a: Longest dimension of the visible surface [m].
        b: Intermediate dimension [m].
        c: Shortest dimension [m].
        esd: Equivalent sphere diameter of the completed shape [m].
        volume: Volume of the completed shape [m^3].
        mass: Volume x specific gravity x water density [kg]; None without a metric scale.
        visible_area: Area of the visible surface [m^2].
        visible_fraction: Visible area over the completed shape's area.
        fer: Flat-and-elongated ratio a / c.
        sphericity: Wadell's sphericity of the completed shape.
        confidence: In [0, 1]: visibility, size and how the rim was found.

    """

    id: int
    centroid: list[float]
    orientation_xyzw: list[float]
    a: float
    b: float
    c: float
    esd: float
    volume: float
    mass: float | None
    visible_area: float
    visible_fraction: float
    fer: float
    sphericity: float
    confidence: float


@dataclass
class GradationCurve:
    """Percent passing and characteristic sizes of rocks (:func:`.segment.gradation.gradation`).

    Attributes:
        size_measure: The size the curve is of (``b``).
        sizes: Each rock's size, ascending [m].
        percent_passing_count: Percent passing by count at each size.
        percent_passing_mass: Percent passing by mass at each size.
        d10: Size at 10 % passing by mass [m]; None when undefined.
        d15: At 15 % [m].
        d30: At 30 % [m].
        d50: At 50 % [m].
        d60: At 60 % [m].
        d85: At 85 % [m].
        d100: The largest size [m].
        cu: ``D60 / D10``; None when undefined.
        cc: ``D30^2 / (D10 D60)``; None when undefined.
        rock_count: Rocks on the curve.
        total_mass: Their mass [kg]; None in a report without a metric scale.

    """

    size_measure: str
    sizes: list[float]
    percent_passing_count: list[float]
    percent_passing_mass: list[float]
    d10: float | None
    d15: float | None
    d30: float | None
    d50: float | None
    d60: float | None
    d85: float | None
    d100: float | None
    cu: float | None
    cc: float | None
    rock_count: int
    total_mass: float | None

    @property
    def characteristic(self) -> dict[str, float | None]:
        """The sizes by mass by key, ``d10`` to ``d100`` (the keys of a class's limits)."""
        return {
            'd10': self.d10,
            'd15': self.d15,
            'd30': self.d30,
            'd50': self.d50,
            'd60': self.d60,
            'd85': self.d85,
            'd100': self.d100,
        }


@dataclass
class Intervals:
    """Confidence intervals of the characteristic sizes (:func:`~.segment.qa.bootstrap_intervals`).

    An interval is ``[lo, hi]``; an end is None where too many draws leave the value undefined.

    Attributes:
        method: How they were found, in words.
        confidence: Two-sided confidence level.
        resamples: Bootstrap draws.
        seed: Seed of the draws.
        scale_rel_uncertainty: The scale's relative uncertainty the lengths were drawn with.
        mass: Interval of each size by mass, by key (``d10`` ... ``d100``) [m].
        count: The same, read off the curve by count [m].
        cu: Interval of Cu.
        cc: Interval of Cc.

    """

    method: str
    confidence: float
    resamples: int
    seed: int
    scale_rel_uncertainty: float
    mass: dict[str, list[float | None]]
    count: dict[str, list[float | None]]
    cu: list[float | None]
    cc: list[float | None]

    def of(self, basis: Basis) -> dict[str, list[float | None]]:
        """Return the intervals by mass or by count."""
        return self.mass if basis == 'mass' else self.count


@dataclass
class LimitRow:
    """One limit of a class and how the measured value stands to it.

    Attributes:
        key: The size limited (``d50``).
        min: Lower bound [m]; None for an open end.
        max: Upper bound [m]; None for an open end.
        value: The measured value [m]; None when undefined.
        interval: Its interval ``[lo, hi]`` [m].
        margin: Distance from the value to the nearer bound, negative outside [m].
        margin_rel: ``margin`` over that bound.
        status: ``pass``, ``fail`` or ``undecided``.
        reason: Why it is not ``pass``, in words ('' when it is).

    """

    key: str
    min: float | None
    max: float | None
    value: float | None
    interval: list[float | None]
    margin: float | None
    margin_rel: float | None
    status: LimitStatus
    reason: str


@dataclass
class ClassDecision:
    """The verdict against a class of the class table (:func:`~.segment.qa.decide`).

    Attributes:
        class_name: The class checked; None when none was asked for.
        basis: Whether its limits are by ``mass`` or by ``count``; None without a class.
        checked: Whether its limits were checked (a metric run with a class).
        passed: True for PASS, False for FAIL, None otherwise.
        verdict: PASS, FAIL, UNDECIDED, NOT CHECKED (no class) or REFUSED (no metric scale).
        reasons: Why the verdict is not PASS, one sentence each.
        limits: Each limit checked.
        standard: The class table's standard ('' without a check).
        edition: Its edition.
        caveat: The class table's caveat.
        note: The class's note.

    """

    class_name: str | None
    basis: Basis | None
    checked: bool
    passed: bool | None
    verdict: Verdict
    reasons: list[str] = field(default_factory=list)
    limits: list[LimitRow] = field(default_factory=list)
    standard: str = ''
    edition: str = ''
    caveat: str = ''
    note: str = ''


@dataclass
class RosinRammler:
    """``P(d) = 100 (1 - exp(-(d / d_c)^n))`` fitted to the percent passing by mass.

    Attributes:
        d_c: Size at 63.2 % passing [m].
        n: Uniformity index.
        rms_pct: RMS residual over the fitted points [percent passing].
        points: Points fitted.

    """

    d_c: float
    n: float
    rms_pct: float
    points: int


@dataclass
class Sieve:
    """Percent passing at one standard size.

    Attributes:
        size: The opening [m].
        size_display: The same in the page's unit (mm or in).
        mass: Percent passing by mass.
        count: Percent passing by count.

    """

    size: float
    size_display: float
    mass: float
    count: float


@dataclass(kw_only=True)
class GradationRecord(GradationCurve):
    """The ``gradation`` of ``report.json``: the curve, its intervals, the verdict, fit and sieves.

    Attributes:
        spec: The verdict against the class asked for (NOT CHECKED without one).
        intervals: Confidence intervals of the sizes, Cu and Cc.
        rosin_rammler: The fit; None when off or with fewer than three points inside 0-100 %.
        sieves: Percent passing at standard sizes; empty without a metric scale.

    """

    spec: ClassDecision
    intervals: Intervals
    rosin_rammler: RosinRammler | None
    sieves: list[Sieve]


@dataclass(frozen=True, kw_only=True)
class MeasureRecord(MeasureParams):
    """The measurement parameters used (every ``measure.*`` field), with what they measure.

    Attributes:
        dimensions: How a, b and c are measured, in words.
        fer: What ``fer`` is.

    """

    dimensions: str = (
        'extents of the visible surface along the principal axes of inertia of its convex hull, '
        'the outermost extent_trim of its area left out at each end'
    )
    fer: str = 'a / c'


@dataclass(frozen=True)
class FloorTry:
    """One floor tried for the smallest rock a mesh resolves (``segment.pipeline.settle_floor``).

    Attributes:
        edges: The floor [median edge lengths] (``SegmentParams.min_rock_edges``).
        min_rock_b: The smallest rock of interest at it, in the mesh's units: the floor, or the
            rock asked for where ``asked``.
        bands: Rocks measured at it, by b in bands a factor sqrt 2 wide from ``min_rock_b`` up
            (the first with any under it).
        cut: Whether the sizes pile up against it (``truncation_warnings``).
        asked: Whether it is at or under the smallest rock asked for (``min_rock_b``, a class),
            which ``min_rock_b`` then is.
        kept: Whether it is the floor the result holds.

    """

    edges: float
    min_rock_b: float
    bands: list[int]
    cut: bool
    asked: bool = False
    kept: bool = False


@dataclass(frozen=True, kw_only=True)
class SegmentationRecord(SegmentParams):
    """The segmentation parameters used (every ``segment.*`` field) and what came of them.

    Attributes:
        scale: The lengths the parameters were scaled with.
        raw_regions: Regions the search grew before the clean-ups.
        segments: Labels after them.
        rocks_measured: Rocks measured (segments too small or flat are not).
        seconds: Time of the segmentation and the measurement of its rocks [s].
        measure: The measurement parameters.
        floors: The floors tried, in order, for a mesh nothing vouches for (another tool's);
            ``min_rock_edges`` is the one kept. Empty where none was searched.

    """

    scale: RockScale
    raw_regions: int
    segments: int
    rocks_measured: int
    seconds: float
    measure: MeasureRecord
    floors: list[FloorTry] = field(default_factory=list)


@dataclass
class MeshRecord:
    """The mesh segmented.

    Attributes:
        faces: Faces segmented.
        vertices: Its vertices.
        source: Where it came from.
        check: What reading it found and dropped; None when the caller checked nothing.
        cloud: How a point cloud was read, levelled and meshed (``mesh.json``'s ``cloud``);
            None for a mesh taken as it is.
        poisson: The Poisson parameters of a mesh made from a cloud; None otherwise.
        model_to_stockpile: From the input's frame into ``frame_id``, for a cloud or a levelled
            foreign mesh; None otherwise.

    """

    faces: int
    vertices: int
    source: str
    check: MeshCheck | None = None
    cloud: dict[str, Any] | None = None
    poisson: dict[str, Any] | None = None
    model_to_stockpile: SimilarityRecord | None = None


@dataclass
class ProvenanceScale:
    """The scale, as the provenance block states it.

    Attributes:
        method: The scale's method.
        rel_uncertainty: Its relative uncertainty, None when unknown.
        how: Where it came from, in words.

    """

    method: ScaleMethod
    rel_uncertainty: float | None
    how: str


@dataclass(frozen=True, kw_only=True)
class ProvenanceRecord(Provenance):
    """The provenance the caller gave (every :class:`~.segment.provenance.Provenance` field).

    Attributes:
        keyframes_used: Keyframes the mesh was made from.
        scale: The scale, in words.

    """

    keyframes_used: int
    scale: ProvenanceScale


@dataclass
class Report:
    """``result/report.json``: the rocks, the gradation, and how they were found.

    Attributes:
        frame_id: Frame of every position (gravity-aligned, z up, ground at z = 0).
        units: ``m``, or ``model`` exactly when the scale's method is ``none``.
        scale: How the mesh was scaled (from ``mesh.json``).
        keyframes: The keyframes' cameras in ``frame_id`` (from ``mesh.json``).
        rocks: The rocks measured.
        gradation: The pile's gradation and its verdict.
        segmentation: Parameters and figures of the segmentation.
        mesh: The mesh segmented.
        warnings: What the user should know, one sentence each.
        provenance: What the result was made from; None until the result folder is written.

    """

    SCHEMA: ClassVar[str] = 'stockpile-report/3'
    #: Version 2 named the class ``class`` and left out empty fields: refused, not misread.
    OLDEST_VERSION: ClassVar[int] = 3
    frame_id: str
    units: Literal['m', 'model']
    scale: ScaleRecord
    keyframes: list[KeyframePose]
    rocks: list[RockRecord]
    gradation: GradationRecord
    segmentation: SegmentationRecord
    mesh: MeshRecord
    warnings: list[str] = field(default_factory=list)
    provenance: ProvenanceRecord | None = None
    schema: str = SCHEMA

    def __post_init__(self) -> None:
        if (self.units == 'm') != self.scale.metric:
            raise ArtefactError(
                f'report.json: units {self.units!r} with scale method {self.scale.method!r}'
            )

    @property
    def metric(self) -> bool:
        """Whether lengths are metres and masses kilograms."""
        return self.units == 'm'
