"""What each stage hands the next: one typed record per artefact, one JSON round trip for all.

=========  ==================  ========================================  =========================
stage      reads               writes (work folder)                      type
=========  ==================  ========================================  =========================
keyframes  bag, photos, video  ``keyframes/keyframes.jsonl`` + PNGs      :class:`KeyframeRecord`
sfm        keyframes           ``sparse/`` (COLMAP) + ``sparse.json``    :class:`SparseSummary`
dense      sparse model        ``dense/dense.ply`` + ``dense.json``      :class:`DenseSummary`
mesh       dense cloud         ``mesh/mesh.ply`` + ``mesh.json``         :class:`MeshInfo`
segment    mesh + MeshInfo     ``result/report.json`` + result folder    :class:`.result.Report`
=========  ==================  ========================================  =========================

The segment stage's record and its parts (rocks, gradation, segmentation, mesh) are in
:mod:`stockpile_ros.result`, beside this module. Every record converts to the JSON it is stored
as with :func:`to_json` and back with :func:`from_json` (one converter, driven by the field types),
and the files carry a schema string that a reader checks: a newer version than this code knows is
refused rather than misread, and so is one older than a record still reads (``OLDEST_VERSION``).
``docs/formats.md`` says what every field means.
"""

from __future__ import annotations

import dataclasses
import json
import math
import types
from dataclasses import dataclass, field
from pathlib import Path
from typing import (
    Any,
    ClassVar,
    Literal,
    Protocol,
    TypeVar,
    Union,
    get_args,
    get_origin,
    get_type_hints,
)

import numpy as np

from .camera import CameraModel
from .errors import StockpileError
from .geometry import Similarity

__all__ = [
    'ArtefactError',
    'DenseSummary',
    'KeyframePose',
    'KeyframeRecord',
    'KeyframeSummary',
    'MeshInfo',
    'ModelImages',
    'OdometryEntry',
    'ScaleMethod',
    'ScaleRecord',
    'SimilarityRecord',
    'SparseSummary',
    'StageResult',
    'WorkFolder',
    'from_json',
    'load',
    'save',
    'to_json',
]

T = TypeVar('T')
ScaleMethod = Literal[
    'target', 'odometry', 'target+odometry', 'given', 'input units', 'sensor', 'none'
]


class ArtefactError(StockpileError):
    """A stage's file that cannot be read as its type (missing key, wrong type, newer schema)."""


@dataclass(frozen=True)
class WorkFolder:
    """Paths of the work folder."""

    root: Path

    @property
    def capture(self) -> Path:
        """The keyframe node's own copy of what it selected (PNGs, ``keyframes.jsonl``)."""
        return self.root / 'capture'

    @property
    def keyframes(self) -> Path:
        """PNG keyframes and ``keyframes.jsonl``: what the reconstruction runs on."""
        return self.root / 'keyframes'

    @property
    def photos(self) -> Path:
        """``photos.json``: each photo of a photo folder, its keyframe and EXIF intrinsics."""
        return self.root / 'photos.json'

    @property
    def sparse(self) -> Path:
        """COLMAP model and ``sparse.json``."""
        return self.root / 'sparse'

    @property
    def dense(self) -> Path:
        """``dense.ply`` and ``dense.json``."""
        return self.root / 'dense'

    @property
    def mesh(self) -> Path:
        """``mesh.ply`` and ``mesh.json``."""
        return self.root / 'mesh'

    @property
    def surface(self) -> Path:
        """The segmentation's copy of the surface it received (``mesh.ply``, ``mesh.json``)."""
        return self.root / 'surface'


@dataclass
class OdometryEntry:
    """The odometry pose at a keyframe's stamp, interpolated between the samples on both sides.

    Attributes:
        position: The base's position in ``frame_id`` [m].
        orientation_xyzw: The base's orientation in ``frame_id``.
        frame_id: The odometry frame (REP 105 ``odom``).
        child_frame_id: The base frame the odometry moves (``base_link``).
        camera_position: The camera's optical centre in ``frame_id`` [m]; None unless the
            transforms link the base to the camera (the base is never taken for the camera).
        camera_orientation_xyzw: The optical frame's orientation in ``frame_id``, with it.

    """

    position: list[float]
    orientation_xyzw: list[float]
    frame_id: str = 'odom'
    child_frame_id: str = 'base_link'
    camera_position: list[float] | None = None
    camera_orientation_xyzw: list[float] | None = None


@dataclass
class KeyframeRecord:
    """One line of ``keyframes.jsonl``: a kept frame.

    Attributes:
        file: PNG file name inside ``keyframes/``.
        stamp_ns: Stamp of the frame [ns].
        index: Index of the frame in its source.
        camera: Camera model from CameraInfo, None when the source has none.
        odometry: Odometry pose at the stamp, None without odometry.
        reason: Why it was kept.
        sharpness: Variance of the Laplacian on the levelled working copy (see
            :mod:`.recon.keyframes`).
        extra: Keys a later writer added, kept as they are.

    """

    SCHEMA: ClassVar[str] = 'stockpile-keyframe/1'
    file: str
    stamp_ns: int
    index: int = 0
    camera: CameraModel | None = None
    odometry: OdometryEntry | None = None
    reason: str = ''
    sharpness: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)

    def to_line(self) -> str:
        """One JSON line, with its schema."""
        return json.dumps({'schema': self.SCHEMA, **to_json(self)})

    @classmethod
    def from_line(cls, line: str) -> KeyframeRecord:
        """Parse one line (lines written before the schema was added read as version 1)."""
        data = json.loads(line)
        if not isinstance(data, dict):
            raise ArtefactError('a keyframes.jsonl line is not an object')
        _check_schema(cls.SCHEMA, str(data.pop('schema', cls.SCHEMA)), 'keyframes.jsonl')
        return from_json(cls, data)


@dataclass
class KeyframeSummary:
    """What the keyframe stage did (printed and published; the keyframes are on disk).

    Attributes:
        frames: Frames seen.
        keyframes: Keyframes held in total.
        new: Keyframes kept by this run (a resumed run keeps the earlier ones).
        decisions: The selector's decisions by reason.
        problems: Messages of the source that could not be read, one line each.

    """

    frames: int
    keyframes: int
    new: int
    decisions: dict[str, int] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)


@dataclass
class ModelImages:
    """One model Structure-from-Motion made, and the keyframes registered in it.

    Attributes:
        registered: Keyframes registered.
        images: Their file names.
        photos: Their photo names (photo sources only).

    """

    registered: int
    images: list[str]
    photos: list[str] = field(default_factory=list)


@dataclass
class SparseSummary:
    """``sparse/sparse.json``: what Structure-from-Motion registered, beside the COLMAP model.

    Attributes:
        registered: Keyframes in the model kept (the largest).
        total: Keyframes offered.
        registered_fraction: ``registered / total``.
        models: Models made.
        points: 3D points of the model kept.
        mean_reprojection_error_px: Over the model kept [px].
        mean_features: Features per keyframe.
        camera: How the intrinsics were found, in words.
        cameras: Each camera of the model (model name, size, parameters).
        matcher: The matcher used.
        matcher_note: Why that one.
        mapper: ``incremental`` or ``global``.
        unregistered: Keyframes left out of the model kept.
        model_images: Every model, the largest first (what the registration gate reads).
        median_triangulation_angle_deg: Of the model's points [deg].
        focal_rel_uncertainty: Relative standard deviation of a focal length bundle adjustment
            refined (:func:`.recon.sfm.focal_uncertainty`), None for a fixed camera.
        unregistered_photos: Photo names of the keyframes left out (photo sources).
        target_focal: Per camera whose focal length the targets' views measured
            (:func:`.recon.sfm.pin_focal`): ``camera_id``, ``sfm_focal_px`` and ``sfm_k1`` (as
            self-calibrated), ``focal_px`` and ``k1``, ``rel_uncertainty`` (jackknife), ``views``,
            ``rms_px`` and ``used`` (the model re-adjusted with them held); empty for a fixed
            camera or without targets.
        gate: The registration gate's report (:class:`.recon.gates.GateReport`), None before.

    """

    SCHEMA: ClassVar[str] = 'stockpile-sparse/1'
    registered: int
    total: int
    registered_fraction: float
    models: int
    points: int
    mean_reprojection_error_px: float
    mean_features: float
    camera: str
    cameras: list[dict[str, Any]]
    matcher: str
    matcher_note: str
    mapper: str
    unregistered: list[str]
    model_images: list[ModelImages]
    median_triangulation_angle_deg: float = math.nan
    focal_rel_uncertainty: float | None = None
    unregistered_photos: list[str] = field(default_factory=list)
    target_focal: list[dict[str, Any]] = field(default_factory=list)
    gate: dict[str, Any] | None = None
    schema: str = SCHEMA


@dataclass
class DenseSummary:
    """``dense/dense.json``: how the dense cloud was made.

    Attributes:
        method: ``sgbm-pairs`` (CPU) or ``colmap-patchmatch`` (CUDA builds of pycolmap).
        gpu: Whether a GPU made it.
        points: Points in ``dense.ply``.
        views: Views used (CPU).
        depth_maps: Views that gave a depth map (CPU).
        raw_points: Depths before the consistency check (CPU).
        consistent_points: Depths that other views agreed with (CPU).
        voxel: Fusion voxel [model units] (CPU).
        off_path: Keyframes left out: SfM put them far from where odometry says the camera was.
        extra: What a method adds beyond these.

    """

    SCHEMA: ClassVar[str] = 'stockpile-dense/1'
    method: str
    gpu: bool
    points: int
    views: int = 0
    depth_maps: int = 0
    raw_points: int = 0
    consistent_points: int = 0
    voxel: float = math.nan
    off_path: list[str] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)
    schema: str = SCHEMA


@dataclass
class ScaleRecord:
    """How a model was brought to metres (``mesh.json`` and ``report.json``).

    Attributes:
        method: Where the scale came from; ``none`` means the lengths are model units.
        metres_per_unit: Metres per model unit (1 when metric input or no scale).
        rel_uncertainty: Relative standard uncertainty of the scale, None when unknown.
        parts: The uncertainty's parts by name (fit, calibration, detections, ...).
        note: In words.

    """

    method: ScaleMethod = 'none'
    metres_per_unit: float = 1.0
    rel_uncertainty: float | None = None
    parts: dict[str, float | None] = field(default_factory=dict)
    note: str = ''

    @property
    def metric(self) -> bool:
        """Whether lengths are metres."""
        return self.method != 'none'

    def summary(self) -> str:
        """One line for a person: the method, its relative uncertainty and the parts of it."""
        unc = '' if self.rel_uncertainty is None else f' +/- {100 * self.rel_uncertainty:.2g} %'
        parts = ', '.join(f'{k} {100 * v:.2g} %' for k, v in self.parts.items() if v is not None)
        return f'{self.method}{unc}' + (f' ({parts})' if parts else '')


@dataclass
class SimilarityRecord:
    """``x_stockpile = scale * R x_model + translation``.

    Attributes:
        scale: Metres per model unit times any ground-fit scale.
        rotation: R, row-major.
        translation: [m].

    """

    scale: float = 1.0
    rotation: list[float] = field(default_factory=lambda: [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0])
    translation: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])

    @classmethod
    def of(cls, sim: Similarity) -> SimilarityRecord:
        """Return the record of a transform."""
        return cls(float(sim.scale), [float(v) for v in np.ravel(sim.rotation)],
                   [float(v) for v in sim.translation])  # fmt: skip

    def similarity(self) -> Similarity:
        """Return the transform, to apply."""
        rotation = np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)
        return Similarity(self.scale, rotation, np.asarray(self.translation, dtype=np.float64))


@dataclass
class KeyframePose:
    """A keyframe's camera in the stockpile frame (camera-to-world, optical frame).

    Attributes:
        stamp_ns: Its stamp [ns].
        position: Optical centre [m].
        orientation_xyzw: Rotates optical-frame vectors into the stockpile frame.
        file: Its file in ``keyframes/``.

    """

    stamp_ns: int
    position: list[float]
    orientation_xyzw: list[float]
    file: str = ''


@dataclass
class MeshInfo:
    """``mesh/mesh.json``: what the surface in ``mesh.ply`` is and how it was made.

    Attributes:
        frame_id: Frame of the vertices (gravity-aligned, z up, ground at z = 0).
        units: ``m``, or ``model`` exactly when the scale's method is ``none``.
        scale: How it was scaled (copied into ``report.json``).
        scale_details: What each scale source gave (targets, odometry, why one was rejected).
        ground_plane_model: ``[a, b, c, d]`` of the ground in SfM model coordinates.
        ground_inliers: Dense points on that plane.
        model_to_stockpile: From SfM model coordinates into ``frame_id``.
        keyframes: The registered keyframes' cameras in ``frame_id``.
        keyframes_off_path: Keyframes left out (see ``dense.json``).
        poisson: Poisson surface parameters and what trimming left.
        cloud: How a point cloud was read, levelled and meshed into it (``docs/formats.md``);
            None for a surface made from the keyframes.

    """

    SCHEMA: ClassVar[str] = 'stockpile-mesh/1'
    scale: ScaleRecord = field(default_factory=ScaleRecord)
    frame_id: str = 'stockpile'
    units: Literal['m', 'model'] = 'model'
    scale_details: dict[str, Any] = field(default_factory=dict)
    ground_plane_model: list[float] = field(default_factory=list)
    ground_inliers: int = 0
    model_to_stockpile: SimilarityRecord = field(default_factory=SimilarityRecord)
    keyframes: list[KeyframePose] = field(default_factory=list)
    keyframes_off_path: list[str] = field(default_factory=list)
    poisson: dict[str, Any] = field(default_factory=dict)
    cloud: dict[str, Any] | None = None
    schema: str = SCHEMA

    def __post_init__(self) -> None:
        if (self.units == 'm') != self.scale.metric:
            raise ArtefactError(
                f'mesh.json: units {self.units!r} with scale method {self.scale.method!r}'
            )


StageResult = KeyframeSummary | SparseSummary | DenseSummary | MeshInfo
"""What a reconstruction stage returns (keyframes, sfm, dense, mesh)."""


def to_json(record: Any) -> Any:
    """Return the JSON form of a record (dataclasses, lists, dicts, numbers; NaN as null)."""
    if dataclasses.is_dataclass(record) and not isinstance(record, type):
        out = {f.name: to_json(getattr(record, f.name)) for f in dataclasses.fields(record)}
        out.update(out.pop('extra', None) or {})
        return out
    if isinstance(record, CameraModel):
        return record.to_dict()
    if isinstance(record, dict):
        return {str(k): to_json(v) for k, v in record.items()}
    if isinstance(record, (list, tuple, np.ndarray)):
        return [to_json(v) for v in record]
    if isinstance(record, (bool, np.bool_)):
        return bool(record)
    if isinstance(record, (int, np.integer)):
        return int(record)
    if isinstance(record, (float, np.floating)):
        return float(record) if math.isfinite(record) else None
    return record


def from_json(cls: type[T], data: Any, where: str = '') -> T:
    """Build a record of type ``cls`` from its JSON form, checking every field's type.

    Keys the type does not name go into its ``extra`` field when it has one and are dropped
    otherwise (a later writer's additions); a missing field takes its default.

    Raises:
        ArtefactError: A field is missing or has the wrong type.

    """
    return _value(cls, data, where or cls.__name__)  # type: ignore[no-any-return]


def _record(cls: type[Any], data: Any, where: str) -> Any:
    if not isinstance(data, dict):
        raise ArtefactError(f'{where}: expected an object, got {type(data).__name__}')
    # Each class of the MRO resolves its annotations in its own module (a record may extend a
    # parameter type defined elsewhere).
    hints = get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    values: dict[str, Any] = {}
    for name, f in fields.items():
        if name == 'extra':
            values[name] = {k: v for k, v in data.items() if k not in fields}
        elif name in data:
            values[name] = _value(hints[name], data[name], f'{where}.{name}')
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ArtefactError(f'{where}: {name!r} missing')
    try:
        return cls(**values)
    except (TypeError, ValueError) as exc:
        raise ArtefactError(f'{where}: {exc}') from exc


def _value(tp: Any, value: Any, where: str) -> Any:
    origin = get_origin(tp)
    if origin in (Union, types.UnionType):
        options = [a for a in get_args(tp) if a is not type(None)]
        if value is None:
            if len(options) < len(get_args(tp)):
                return None
            raise ArtefactError(f'{where}: null where a value is needed')
        return _value(options[0], value, where)
    if origin is Literal:
        if value not in get_args(tp):
            raise ArtefactError(f'{where}: {value!r} is not one of {list(get_args(tp))}')
        return value
    if origin is list:
        if not isinstance(value, list):
            raise ArtefactError(f'{where}: expected a list')
        (item,) = get_args(tp)
        return [_value(item, v, f'{where}[{i}]') for i, v in enumerate(value)]
    if origin is dict:
        if not isinstance(value, dict):
            raise ArtefactError(f'{where}: expected an object')
        _, item = get_args(tp)
        return {str(k): _value(item, v, f'{where}.{k}') for k, v in value.items()}
    if tp is CameraModel:
        return CameraModel.from_dict(value)
    if dataclasses.is_dataclass(tp):
        return _record(tp, value, where)  # type: ignore[arg-type]
    if tp is Any:
        return value
    if tp is float:
        # JSON has no NaN: an undefined number is written as null.
        if value is None:
            return math.nan
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
    elif isinstance(value, tp) and not (tp is int and isinstance(value, bool)):
        return value
    raise ArtefactError(f'{where}: expected {tp.__name__}, got {value!r}')


def _check_schema(expected: str, found: str, where: str, oldest: int = 1) -> None:
    family, _, version = expected.rpartition('/')
    got_family, _, got_version = found.rpartition('/')
    if got_family != family:
        raise ArtefactError(f'{where}: schema {found!r}, expected {expected!r}')
    if not got_version.isdigit() or int(got_version) > int(version):
        raise ArtefactError(f'{where}: schema {found!r} is newer than this stockpile_ros reads '
                            f'({expected!r}); update it')  # fmt: skip
    if int(got_version) < oldest:
        raise ArtefactError(f'{where}: schema {found!r} is older than this stockpile_ros reads '
                            f'({expected!r}); make it again')  # fmt: skip


def save(record: Any, path: Path) -> None:
    """Write a record with a schema as indented JSON, through a temporary name."""
    tmp = path.with_name(f'.{path.name}.tmp')
    tmp.write_text(json.dumps(to_json(record), indent=1) + '\n')
    tmp.replace(path)


class _Schematic(Protocol):
    SCHEMA: ClassVar[str]


S = TypeVar('S', bound=_Schematic)


def load(cls: type[S], path: Path) -> S:
    """Read a record with a schema, checking the schema and every field.

    A record that no longer reads its earliest versions names the oldest it reads in an
    ``OLDEST_VERSION`` class attribute (1 otherwise).

    Raises:
        ArtefactError: Not JSON, another schema, a newer or too old version, or a bad field.

    """
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ArtefactError(f'{path}: {exc}') from exc
    expected = cls.SCHEMA
    if not isinstance(data, dict):
        raise ArtefactError(f'{path}: expected an object')
    # sparse.json and dense.json were written without one before version 1 was named.
    oldest = int(getattr(cls, 'OLDEST_VERSION', 1))
    _check_schema(expected, str(data.get('schema', expected)), str(path), oldest)
    data['schema'] = expected
    return from_json(cls, data, str(path))
