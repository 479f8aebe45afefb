"""Point clouds from files: PLY without faces, OBJ vertices, LAS/LAZ, XYZ/CSV/TXT columns.

Every reader returns a :class:`Cloud` in the file's own units and frame; :func:`is_mesh_file`
tells a file with faces (which ``stockpile segment`` reads as a mesh) from a cloud. Points that
are not finite are dropped and counted; colours are 8-bit (LAS's 16-bit channels are scaled).
Text columns are ``x y z [nx ny nz] [r g b]``, comma, semicolon or whitespace separated, with an
optional header naming them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import MeshError, reading
from ..meshio import check_ply_size, eight_bit, read_obj, read_ply_header

__all__ = ['CLOUD_SUFFIXES', 'Cloud', 'is_mesh_file', 'read_cloud']

F64 = npt.NDArray[np.float64]
U8 = npt.NDArray[np.uint8]

CLOUD_SUFFIXES = ('.ply', '.obj', '.las', '.laz', '.xyz', '.csv', '.txt', '.pts')
"""File suffixes :func:`read_cloud` reads (case-insensitive)."""

# Header names of each column group in a text file (lower case, '//' and '_' prefixes dropped).
_NAMES = {
    'x': ('x',), 'y': ('y',), 'z': ('z',),
    'nx': ('nx', 'normal_x', 'normalx'), 'ny': ('ny', 'normal_y', 'normaly'),
    'nz': ('nz', 'normal_z', 'normalz'),
    'r': ('r', 'red'), 'g': ('g', 'green'), 'b': ('b', 'blue'),
}  # fmt: skip
# Unit normals from a tool are written to a few decimals: a norm this far from 1 is no normal.
_UNIT_TOLERANCE = 0.02


@dataclass
class Cloud:
    """Points with optional normals and colours, in the units and frame of their file.

    Attributes:
        points: Nx3 positions.
        normals: Nx3 normals as given (unit length, sign as the tool wrote it) or None.
        colors: Nx3 8-bit colours or None.
        source: The file, for messages.
        format: ``ply``, ``obj``, ``las``, ``laz`` or ``text``.
        warnings: What was dropped or guessed, one sentence each.

    """

    points: F64
    normals: F64 | None
    colors: U8 | None
    source: str
    format: str
    warnings: list[str] = field(default_factory=list)


def _finish(cloud: Cloud) -> Cloud:
    """Drop points with a non-finite coordinate (with their normals, colours); refuse none left."""
    good = np.isfinite(cloud.points).all(axis=1)
    if cloud.normals is not None:
        norm = np.linalg.norm(cloud.normals, axis=1)
        usable = np.isfinite(norm) & (norm > 0)
        if not usable[good].all():
            cloud.warnings.append(
                f'{int((good & ~usable).sum())} normals are zero or not finite: every normal '
                'is estimated from the points instead'
            )
            cloud.normals = None
        else:
            cloud.normals = cloud.normals / np.where(usable, norm, 1.0)[:, None]
    if not good.all():
        cloud.warnings.append(f'{int((~good).sum())} points with a non-finite coordinate dropped')
        cloud.points = cloud.points[good]
        cloud.normals = None if cloud.normals is None else cloud.normals[good]
        cloud.colors = None if cloud.colors is None else cloud.colors[good]
    if len(cloud.points) == 0:
        raise MeshError(f'{cloud.source}: no points')
    return cloud


def is_mesh_file(path: str | Path) -> bool:
    """Whether ``path`` is read as a mesh: a PLY with faces (or no vertex), an OBJ with ``f`` lines.

    Any other suffix than :data:`CLOUD_SUFFIXES` (STL, OFF) is a mesh too.

    Raises:
        MeshError: A PLY whose header cannot be parsed; an unreadable file.

    """
    file = Path(path)
    suffix = file.suffix.lower()
    with reading(file, 'mesh file (nor point cloud)'):
        if suffix == '.ply':
            with file.open('rb') as stream:
                raw = stream.read(1 << 16)
            if not raw.startswith(b'ply'):
                return True  # the mesh reader names what it is not
            header = read_ply_header(raw, file)
            face, vertex = header.element('face'), header.element('vertex')
            # MeshLab writes clouds with an empty face element; no vertex at all is no cloud.
            return (face is not None and face.count > 0) or vertex is None or vertex.count == 0
        if suffix == '.obj':
            with file.open('rb') as stream:
                return any(line.startswith(b'f ') for line in stream)
    return suffix not in CLOUD_SUFFIXES


def _read_ply(path: Path) -> Cloud:
    import open3d

    o3d: Any = open3d
    raw = path.read_bytes()
    header = read_ply_header(raw, path)
    check_ply_size(header, len(raw), path)
    del raw
    pcd = o3d.io.read_point_cloud(str(path), format='ply')
    points = np.asarray(pcd.points, dtype=np.float64)
    if len(points) == 0:
        raise MeshError(f'{path}: a PLY without points open3d can read')
    normals = np.asarray(pcd.normals, dtype=np.float64) if pcd.has_normals() else None
    colors = eight_bit(np.asarray(pcd.colors)) if pcd.has_colors() else None
    return Cloud(points, normals, colors, str(path), 'ply')


def _read_obj(path: Path) -> Cloud:
    obj = read_obj(path)
    if not len(obj.vertices):
        raise MeshError(f'{path}: an OBJ without vertices')
    cloud = Cloud(obj.vertices, None, obj.colors, str(path), 'obj')
    # Without faces an OBJ has no vertex-normal pairing but their order: equal counts only.
    if obj.normals is not None and len(obj.normals) == len(obj.vertices):
        cloud.normals = obj.normals
    return cloud


def _read_las(path: Path) -> Cloud:
    import laspy

    try:
        las = laspy.read(str(path))
    except OSError:
        raise
    except Exception as exc:  # laspy raises its own and plain errors for bad or unsupported files
        raise MeshError(f'{path}: not a LAS/LAZ file laspy can read ({exc})') from None
    points = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])
    names = set(las.point_format.dimension_names)
    colors = None
    if {'red', 'green', 'blue'} <= names:
        rgb = np.column_stack([np.asarray(las.red), np.asarray(las.green), np.asarray(las.blue)])
        if rgb.any():
            colors = eight_bit(rgb)
    normals = None
    extra = {n.lower(): n for n in las.point_format.extra_dimension_names}
    for keys in (('nx', 'ny', 'nz'), ('normalx', 'normaly', 'normalz'),
                 ('normal_x', 'normal_y', 'normal_z')):  # fmt: skip
        if all(k in extra for k in keys):
            normals = np.column_stack([np.asarray(las[extra[k]], dtype=np.float64) for k in keys])
            break
    return Cloud(points.astype(np.float64), normals, colors, str(path), path.suffix[1:].lower())


def _columns_from_header(words: list[str], path: Path) -> dict[str, int]:
    index: dict[str, int] = {}
    for i, word in enumerate(words):
        name = word.lower().lstrip('/').lstrip('_')
        for key, aliases in _NAMES.items():
            if name in aliases and key not in index:
                index[key] = i
    if not {'x', 'y', 'z'} <= index.keys():
        raise MeshError(f'{path}: header {" ".join(words)!r} names no x, y and z columns')
    return index


def _columns_by_count(data: F64, path: Path, warnings: list[str]) -> dict[str, int]:
    """Which columns are which without a header: 3, 6 or 9 columns; otherwise x y z first."""
    xyz = {'x': 0, 'y': 1, 'z': 2}
    count = data.shape[1]
    if count == 9:
        return {**xyz, 'nx': 3, 'ny': 4, 'nz': 5, 'r': 6, 'g': 7, 'b': 8}
    if count == 6:
        rest = data[:, 3:6]
        norm = np.linalg.norm(rest, axis=1)
        if np.all(np.abs(norm - 1.0) < _UNIT_TOLERANCE):
            return {**xyz, 'nx': 3, 'ny': 4, 'nz': 5}
        if np.all(rest == np.round(rest)) and rest.min() >= 0 and rest.max() <= 255:
            return {**xyz, 'r': 3, 'g': 4, 'b': 5}
        raise MeshError(
            f'{path}: six columns without a header whose last three are neither unit normals nor '
            '0-255 colours; add a header line naming the columns (x y z nx ny nz r g b)'
        )
    if count > 3:
        warnings.append(
            f'{count} columns without a header: x, y, z taken from the first three, the rest '
            'ignored (a header line naming them, x y z nx ny nz r g b, makes them read)'
        )
    return xyz


def _read_text(path: Path) -> Cloud:
    with path.open('r', errors='replace') as stream:
        first = ''
        for line in stream:
            if line.strip():
                first = line
                break
    separator = ',' if ',' in first else (';' if ';' in first else None)
    words = [w for w in re.split(r'[,;\s]+', first.strip()) if w]
    try:
        [float(w) for w in words]
        header = None
    except ValueError:
        header = words
    try:
        data = np.loadtxt(path, delimiter=separator, skiprows=1 if header else 0,
                          ndmin=2, comments='#')  # fmt: skip
    except ValueError as exc:
        raise MeshError(f'{path}: not a table of numbers ({exc})') from None
    warnings: list[str] = []
    if data.size == 0 or data.shape[1] < 3:
        raise MeshError(f'{path}: fewer than three columns (x y z)')
    cols = _columns_from_header(header, path) if header else _columns_by_count(data, path, warnings)
    if max(cols.values()) >= data.shape[1]:
        raise MeshError(f'{path}: the header names more columns than the rows hold')
    cloud = Cloud(data[:, [cols['x'], cols['y'], cols['z']]], None, None, str(path), 'text',
                  warnings)  # fmt: skip
    if {'nx', 'ny', 'nz'} <= cols.keys():
        cloud.normals = data[:, [cols['nx'], cols['ny'], cols['nz']]]
    if {'r', 'g', 'b'} <= cols.keys():
        cloud.colors = eight_bit(data[:, [cols['r'], cols['g'], cols['b']]])
    return cloud


def read_cloud(path: str | Path) -> Cloud:
    """Read a point cloud file by its suffix (see :data:`CLOUD_SUFFIXES`).

    Raises:
        MeshError: Missing, unreadable or malformed file, unknown suffix, or no finite point.

    """
    file = Path(path)
    suffix = file.suffix.lower()
    readers = {'.ply': _read_ply, '.obj': _read_obj, '.las': _read_las, '.laz': _read_las}
    reader = readers.get(suffix, _read_text if suffix in CLOUD_SUFFIXES else None)
    if reader is None:
        raise MeshError(
            f'{file}: unknown point cloud suffix {file.suffix!r} (known: '
            f'{", ".join(CLOUD_SUFFIXES)})'
        )
    with reading(file, 'file (a point cloud)'):
        return _finish(reader(file))
