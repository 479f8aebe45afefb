"""Builders of every message the project publishes, for rosbags and rclpy alike.

Standard types: ``sensor_msgs/PointCloud2`` (x, y, z, rgb, label),
``visualization_msgs/MarkerArray`` (one coloured shape and one size label per rock) and
``diagnostic_msgs/DiagnosticArray``. Our types
(``stockpile_msgs``) are built from the report's records (:mod:`stockpile_ros.result`): an
undefined number (None) becomes NaN in float fields.

Each builder takes a :class:`~stockpile_ros.ros.messages.MessageFactory` first, as in
:mod:`stockpile_ros.ros.messages`.
"""

from __future__ import annotations

import colorsys
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from ..artefacts import ScaleRecord
from ..result import GradationRecord, RockRecord
from .messages import MessageFactory, header, pose

__all__ = [
    'DIAGNOSTIC_LEVELS',
    'PIPELINE_STATES',
    'diagnostic_array',
    'gradation_msg',
    'marker_array',
    'mesh_marker_array',
    'pipeline_status',
    'pointcloud2',
    'pointcloud2_arrays',
    'rock_array',
    'rock_color',
    'rock_msg',
]

DIAGNOSTIC_LEVELS = ('OK', 'WARN', 'ERROR', 'STALE')
"""``diagnostic_msgs/DiagnosticStatus`` levels, in the order of their values 0..3."""

PIPELINE_STATES = ('IDLE', 'COLLECTING', 'RECONSTRUCTING', 'SEGMENTING', 'DONE', 'FAILED')
"""``stockpile_msgs/PipelineStatus`` states, in the order of their values 0..5."""

# PointField datatype -> numpy type (sensor_msgs/PointField constants 1..8).
_FIELD_DTYPES = {1: 'i1', 2: 'u1', 3: 'i2', 4: 'u2', 5: 'i4', 6: 'u4', 7: 'f4', 8: 'f8'}
_FLOAT32 = 7
_UINT32 = 6

_IDENTITY_XYZW = (0.0, 0.0, 0.0, 1.0)


def _nan(value: float | None) -> float:
    """Return the number, NaN for None."""
    return math.nan if value is None else float(value)


def _get(d: Mapping[str, Any], key: str, what: str) -> Any:
    try:
        return d[key]
    except KeyError:
        raise ValueError(f'{what} has no {key!r} (keys: {", ".join(sorted(d))})') from None


def pointcloud2(
    f: MessageFactory,
    points: npt.ArrayLike,
    colors: npt.ArrayLike | None,
    labels: npt.ArrayLike | None,
    stamp_ns: int,
    frame_id: str,
) -> Any:
    """Build an unordered ``sensor_msgs/PointCloud2`` (height 1, little-endian).

    Fields: ``x``, ``y``, ``z`` (FLOAT32); with colours ``rgb`` (FLOAT32 holding the bits of the
    uint32 ``0x00RRGGBB``, as PCL and RViz expect); with labels ``label`` (UINT32, the rock id,
    0 = ground or unassigned).

    Args:
        f: Message factory.
        points: Nx3 positions [m].
        colors: Nx3 uint8 RGB, or None.
        labels: N non-negative integer labels, or None.
        stamp_ns: Header stamp [ns].
        frame_id: Header frame.

    Raises:
        ValueError: Shapes disagree, colours are not 0..255 integers, or a label is negative.

    """
    xyz = np.asarray(points, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise ValueError(f'points must be Nx3, got shape {xyz.shape}')
    n = xyz.shape[0]
    names = ['x', 'y', 'z']
    formats = ['<f4', '<f4', '<f4']
    if colors is not None:
        names.append('rgb')
        formats.append('<u4')
    if labels is not None:
        names.append('label')
        formats.append('<u4')
    record = np.zeros(n, dtype=np.dtype({'names': names, 'formats': formats}))
    record['x'], record['y'], record['z'] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    if colors is not None:
        rgb = np.asarray(colors)
        if rgb.shape != (n, 3):
            raise ValueError(f'colors must be {n}x3, got shape {rgb.shape}')
        if not np.issubdtype(rgb.dtype, np.integer) or (
            rgb.size and (rgb.min() < 0 or rgb.max() > 255)
        ):
            raise ValueError(f'colors must be integers 0..255 (uint8 RGB), got {rgb.dtype}')
        rgb = rgb.astype(np.uint32)
        record['rgb'] = (rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]
    if labels is not None:
        lab = np.asarray(labels).reshape(-1)
        if lab.shape != (n,):
            raise ValueError(f'labels must have {n} values, got {lab.shape[0]}')
        if lab.size and lab.min() < 0:
            raise ValueError('labels must be non-negative (0 = ground or unassigned)')
        record['label'] = lab.astype(np.uint32)
    field_cls = f.cls('sensor_msgs/msg/PointField')
    # Every field is 4 bytes, packed in order.
    offsets = {name: 4 * i for i, name in enumerate(names)}
    fields = [
        field_cls(
            name=name,
            offset=offsets[name],
            datatype=_UINT32 if name == 'label' else _FLOAT32,
            count=1,
        )
        for name in names
    ]
    return f.cls('sensor_msgs/msg/PointCloud2')(
        header=header(f, stamp_ns, frame_id),
        height=1,
        width=n,
        fields=fields,
        is_bigendian=False,
        point_step=record.dtype.itemsize,
        row_step=record.dtype.itemsize * n,
        data=f.u8(record.view(np.uint8)),
        is_dense=bool(np.all(np.isfinite(xyz))),
    )


def pointcloud2_arrays(
    msg: Any,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8] | None, npt.NDArray[np.int64] | None]:
    """Read points, colours and labels back from a ``sensor_msgs/PointCloud2``.

    Returns:
        Nx3 float32 points, Nx3 uint8 RGB colours (None without an ``rgb`` field), N labels (None
        without a ``label`` field).

    Raises:
        ValueError: No x/y/z fields, an unknown field type, or data shorter than the header says.

    """
    order = '>' if msg.is_bigendian else '<'
    spec = {
        fld.name: (int(fld.offset), order + _FIELD_DTYPES[int(fld.datatype)])
        for fld in msg.fields
        if int(fld.datatype) in _FIELD_DTYPES
    }
    if not {'x', 'y', 'z'} <= spec.keys():
        raise ValueError(f'PointCloud2 has no x, y, z fields (fields: {", ".join(spec)})')
    n = int(msg.width) * int(msg.height)
    step = int(msg.point_step)
    data = np.ascontiguousarray(np.asarray(msg.data, dtype=np.uint8).reshape(-1))
    if data.size < n * step:
        raise ValueError(f'PointCloud2 data holds {data.size} bytes, {n} points need {n * step}')
    dtype = np.dtype(
        {
            'names': list(spec),
            'formats': [fmt for _, fmt in spec.values()],
            'offsets': [off for off, _ in spec.values()],
            'itemsize': step,
        }
    )
    record = data[: n * step].view(dtype)
    xyz = np.stack([record['x'], record['y'], record['z']], axis=1).astype(np.float32)
    colors = None
    if 'rgb' in spec:
        field = np.ascontiguousarray(record['rgb'])
        # Reinterpret the float's bits in the stored byte order, then go native.
        packed = field.view(field.dtype.str[0] + 'u4').astype(np.uint32)
        colors = np.stack([(packed >> s) & 0xFF for s in (16, 8, 0)], axis=1).astype(np.uint8)
    labels = record['label'].astype(np.int64) if 'label' in spec else None
    return xyz, colors, labels


def rock_color(rock_id: int) -> tuple[float, float, float]:
    """Return a distinct, stable RGB colour (0..1) per rock id (golden-angle hues); grey for 0."""
    if rock_id <= 0:
        return (0.6, 0.6, 0.6)
    hue = (rock_id * 0.618033988749895) % 1.0
    return colorsys.hsv_to_rgb(hue, 0.65, 0.95)


def _marker(
    f: MessageFactory,
    hdr: Any,
    ns: str,
    marker_id: int,
    kind: str,
    action: str = 'ADD',
    *,
    position: Sequence[float] = (0.0, 0.0, 0.0),
    orientation_xyzw: Sequence[float] = _IDENTITY_XYZW,
    scale: Sequence[float] = (1.0, 1.0, 1.0),
    rgba: Sequence[float] = (1.0, 1.0, 1.0, 1.0),
    points: list[Any] | None = None,
    colors: list[Any] | None = None,
    text: str = '',
) -> Any:
    """Build a ``visualization_msgs/Marker`` with every field set (rosbags' Jazzy needs all)."""
    cls = f.cls('visualization_msgs/msg/Marker')
    empty_image = f.cls('sensor_msgs/msg/CompressedImage')(header=hdr, format='', data=f.u8(b''))
    return cls(
        header=hdr,
        ns=ns,
        id=marker_id,
        type=getattr(cls, kind),
        action=getattr(cls, action),
        pose=pose(f, position, orientation_xyzw),
        scale=f.cls('geometry_msgs/msg/Vector3')(x=scale[0], y=scale[1], z=scale[2]),
        color=f.cls('std_msgs/msg/ColorRGBA')(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3]),
        lifetime=f.cls('builtin_interfaces/msg/Duration')(sec=0, nanosec=0),
        frame_locked=False,
        points=points or [],
        colors=colors or [],
        texture_resource='',
        texture=empty_image,
        uv_coordinates=[],
        text=text,
        mesh_resource='',
        mesh_file=f.cls('visualization_msgs/msg/MeshFile')(filename='', data=f.u8(b'')),
        mesh_use_embedded_materials=False,
    )


def marker_array(
    f: MessageFactory,
    rocks: Sequence[RockRecord],
    stamp_ns: int,
    frame_id: str,
    vertices: npt.ArrayLike | None = None,
    faces: npt.ArrayLike | None = None,
    face_labels: npt.ArrayLike | None = None,
) -> Any:
    """Build a ``visualization_msgs/MarkerArray`` showing each rock and its size.

    The array starts with a DELETEALL marker (clears the previous result in RViz). Then, per rock
    (``rock_color`` colours): namespace ``rocks``, id = rock id, a TRIANGLE_LIST of the rock's faces
    when the labelled mesh is given, else a CUBE at the centroid with the principal-axes orientation
    (``orientation_xyzw``) and edges a, b, c; namespace ``rock_labels``, id = rock id, a
    TEXT_VIEW_FACING above the rock: ``"<id>: b <b> cm"``.

    Args:
        f: Message factory.
        rocks: The report's rocks.
        stamp_ns: Header stamp [ns].
        frame_id: Header frame (the frame of the centroids and mesh).
        vertices: Vx3 mesh vertices, optional.
        faces: Fx3 vertex indices, optional (with ``vertices`` and ``face_labels``).
        face_labels: F rock ids per face (0 = ground), optional.

    Raises:
        ValueError: Only part of the mesh is given.

    """
    hdr = header(f, stamp_ns, frame_id)
    mesh = (vertices, faces, face_labels)
    if any(m is not None for m in mesh) and any(m is None for m in mesh):
        raise ValueError('give vertices, faces and face_labels together, or none of them')
    verts = tri = lab = None
    if vertices is not None and faces is not None and face_labels is not None:
        verts = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        tri = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        lab = np.asarray(face_labels).reshape(-1)
        if lab.shape[0] != tri.shape[0]:
            raise ValueError(f'{tri.shape[0]} faces but {lab.shape[0]} face labels')
    point_cls = f.cls('geometry_msgs/msg/Point')
    markers = [_marker(f, hdr, '', 0, 'CUBE', 'DELETEALL')]
    for rock in rocks:
        rock_id = rock.id
        centroid = [float(v) for v in rock.centroid]
        a, b, c = rock.a, rock.b, rock.c
        quat = [float(v) for v in rock.orientation_xyzw]
        red, green, blue = rock_color(rock_id)
        corners = None
        if verts is not None and tri is not None and lab is not None:
            corners = verts[tri[lab == rock_id].reshape(-1)]
        if corners is not None and len(corners):
            pts = [point_cls(x=float(x), y=float(y), z=float(z)) for x, y, z in corners]
            markers.append(
                _marker(
                    f,
                    hdr,
                    'rocks',
                    rock_id,
                    'TRIANGLE_LIST',
                    points=pts,
                    rgba=(red, green, blue, 1.0),
                )
            )
        else:
            box = [v if math.isfinite(v) and v > 0 else 0.01 for v in (a, b, c)]
            markers.append(
                _marker(
                    f,
                    hdr,
                    'rocks',
                    rock_id,
                    'CUBE',
                    position=centroid,
                    orientation_xyzw=quat,
                    scale=box,
                    rgba=(red, green, blue, 0.7),
                )
            )
        height = min(max(0.5 * b, 0.03), 0.3) if math.isfinite(b) else 0.05
        top = list(centroid)
        top[2] += (0.5 * c if math.isfinite(c) else 0.0) + height
        size = f'{100 * b:.1f} cm' if math.isfinite(b) else 'unknown'
        markers.append(
            _marker(
                f,
                hdr,
                'rock_labels',
                rock_id,
                'TEXT_VIEW_FACING',
                position=top,
                scale=(height, height, height),
                text=f'{rock_id}: b {size}',
            )
        )
    return f.cls('visualization_msgs/msg/MarkerArray')(markers=markers)


def mesh_marker_array(
    f: MessageFactory,
    vertices: npt.ArrayLike,
    faces: npt.ArrayLike,
    stamp_ns: int,
    frame_id: str,
    colors: npt.ArrayLike | None = None,
    ns: str = 'mesh',
) -> Any:
    """Build a ``visualization_msgs/MarkerArray`` holding one mesh as a TRIANGLE_LIST (id 0).

    Args:
        f: Message factory.
        vertices: Vx3 vertices.
        faces: Fx3 vertex indices.
        stamp_ns: Header stamp [ns].
        frame_id: Header frame.
        colors: Vx3 uint8 vertex colours (one colour per triangle corner in the marker), or None
            for a uniform grey.
        ns: Marker namespace.

    """
    hdr = header(f, stamp_ns, frame_id)
    verts = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    corners = np.asarray(faces, dtype=np.int64).reshape(-1)
    point_cls = f.cls('geometry_msgs/msg/Point')
    pts = [point_cls(x=float(x), y=float(y), z=float(z)) for x, y, z in verts[corners]]
    rgba = None
    if colors is not None:
        color_cls = f.cls('std_msgs/msg/ColorRGBA')
        rgb = np.asarray(colors, dtype=np.float64).reshape(-1, 3)[corners] / 255.0
        rgba = [color_cls(r=float(r), g=float(g), b=float(b), a=1.0) for r, g, b in rgb]
    marker = _marker(
        f, hdr, ns, 0, 'TRIANGLE_LIST', points=pts, colors=rgba, rgba=(0.7, 0.7, 0.7, 1.0)
    )
    return f.cls('visualization_msgs/msg/MarkerArray')(markers=[marker])


def _level(status_cls: Any, level: int | str) -> Any:
    """Level constant of the library (rclpy wants bytes, rosbags an int) from a name or 0..3."""
    if isinstance(level, str):
        name = level.upper()
        if name not in DIAGNOSTIC_LEVELS:
            raise ValueError(
                f'unknown diagnostic level {level!r} (use {", ".join(DIAGNOSTIC_LEVELS)})'
            )
    else:
        if not 0 <= int(level) < len(DIAGNOSTIC_LEVELS):
            raise ValueError(f'diagnostic level {level} is not in 0..3')
        name = DIAGNOSTIC_LEVELS[int(level)]
    return getattr(status_cls, name)


def diagnostic_array(
    f: MessageFactory, stamp_ns: int, entries: Sequence[Mapping[str, Any]], frame_id: str = ''
) -> Any:
    """Build a ``diagnostic_msgs/DiagnosticArray``.

    Args:
        f: Message factory.
        stamp_ns: Header stamp [ns].
        entries: One dict per status: ``name``, ``level`` (``"OK"``, ``"WARN"``, ``"ERROR"``,
            ``"STALE"`` or 0..3), ``message``, optional ``hardware_id`` and ``values`` (a mapping
            whose values are written with ``str``).
        frame_id: Header frame (usually empty).

    Raises:
        ValueError: An entry lacks ``name``/``level`` or has an unknown level.

    """
    status_cls = f.cls('diagnostic_msgs/msg/DiagnosticStatus')
    key_value = f.cls('diagnostic_msgs/msg/KeyValue')
    status = []
    for entry in entries:
        name = str(_get(entry, 'name', 'diagnostic entry'))
        status.append(
            status_cls(
                level=_level(status_cls, _get(entry, 'level', f'diagnostic entry {name}')),
                name=name,
                message=str(entry.get('message', '')),
                hardware_id=str(entry.get('hardware_id', '')),
                values=[
                    key_value(key=str(k), value=str(v))
                    for k, v in (entry.get('values') or {}).items()
                ],
            )
        )
    return f.cls('diagnostic_msgs/msg/DiagnosticArray')(
        header=header(f, stamp_ns, frame_id), status=status
    )


def rock_msg(f: MessageFactory, rock: RockRecord, stamp_ns: int, frame_id: str) -> Any:
    """Build ``stockpile_msgs/Rock`` from a report's rock.

    ``fer`` fills ``flat_elongated_ratio``; a mass of None (no metric scale) becomes NaN.
    """
    x, y, z = (float(v) for v in rock.centroid)
    qx, qy, qz, qw = (float(v) for v in rock.orientation_xyzw)
    return f.cls('stockpile_msgs/msg/Rock')(
        header=header(f, stamp_ns, frame_id),
        id=rock.id,
        centroid=f.cls('geometry_msgs/msg/Point')(x=x, y=y, z=z),
        orientation=f.cls('geometry_msgs/msg/Quaternion')(x=qx, y=qy, z=qz, w=qw),
        a=rock.a,
        b=rock.b,
        c=rock.c,
        esd=rock.esd,
        volume=rock.volume,
        mass=_nan(rock.mass),
        visible_area=rock.visible_area,
        visible_fraction=rock.visible_fraction,
        flat_elongated_ratio=rock.fer,
        sphericity=rock.sphericity,
        confidence=rock.confidence,
    )


def rock_array(
    f: MessageFactory,
    rocks: Sequence[RockRecord],
    scale: ScaleRecord,
    stamp_ns: int,
    frame_id: str,
) -> Any:
    """Build ``stockpile_msgs/RockArray`` from the report's rocks and scale.

    ``metric`` is false when the scale method is ``"none"``; an unknown ``rel_uncertainty``
    becomes NaN.
    """
    return f.cls('stockpile_msgs/msg/RockArray')(
        header=header(f, stamp_ns, frame_id),
        rocks=[rock_msg(f, rock, stamp_ns, frame_id) for rock in rocks],
        metric=scale.metric,
        scale_method=scale.method,
        scale_rel_uncertainty=_nan(scale.rel_uncertainty),
    )


def gradation_msg(
    f: MessageFactory,
    gradation: GradationRecord,
    stamp_ns: int,
    frame_id: str,
    units: str = 'm',
) -> Any:
    """Build ``stockpile_msgs/Gradation`` from the report's gradation.

    Undefined sizes become NaN; without a class the class is empty, not checked, not passed
    (``verdict`` NOT CHECKED). ``units`` is the report's (``m``, or ``model`` without a metric
    scale).
    """
    spec = gradation.spec
    return f.cls('stockpile_msgs/msg/Gradation')(
        header=header(f, stamp_ns, frame_id),
        size_measure=gradation.size_measure,
        sizes=f.f64(gradation.sizes),
        percent_passing_count=f.f64(gradation.percent_passing_count),
        percent_passing_mass=f.f64(gradation.percent_passing_mass),
        rock_count=gradation.rock_count,
        spec_class=spec.class_name or '',
        checked=spec.checked,
        passed=bool(spec.passed),
        verdict=spec.verdict,
        reasons=list(spec.reasons),
        units=units,
        **{key: _nan(value) for key, value in gradation.characteristic.items()},
        cu=_nan(gradation.cu),
        cc=_nan(gradation.cc),
        total_mass=_nan(gradation.total_mass),
    )


def pipeline_status(
    f: MessageFactory,
    stamp_ns: int,
    state: int | str,
    stage: str,
    progress: float,
    keyframes: int,
    coverage: float,
    message: str,
    advice: str = '',
    frame_id: str = '',
) -> Any:
    """Build ``stockpile_msgs/PipelineStatus``.

    Args:
        f: Message factory.
        stamp_ns: Header stamp [ns].
        state: A name of :data:`PIPELINE_STATES` (any case, with or without ``STATE_``) or 0..5.
        stage: The stage running or last run.
        progress: 0..1 within the stage.
        keyframes: Keyframes held.
        coverage: 0..1, how well the pile is covered.
        message: What happened.
        advice: What the operator should do, when something went wrong.
        frame_id: Header frame (usually empty).

    Raises:
        ValueError: Unknown state.

    """
    if isinstance(state, str):
        name = state.upper().removeprefix('STATE_')
        if name not in PIPELINE_STATES:
            raise ValueError(f'unknown state {state!r} (use {", ".join(PIPELINE_STATES)})')
        value = PIPELINE_STATES.index(name)
    else:
        value = int(state)
        if not 0 <= value < len(PIPELINE_STATES):
            raise ValueError(f'state {state} is not in 0..{len(PIPELINE_STATES) - 1}')
    return f.cls('stockpile_msgs/msg/PipelineStatus')(
        header=header(f, stamp_ns, frame_id),
        state=value,
        stage=stage,
        progress=float(progress),
        keyframes=int(keyframes),
        coverage=float(coverage),
        message=message,
        advice=advice,
    )
