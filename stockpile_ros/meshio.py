"""Triangle meshes with a per-face label (rock id, 0 for ground or unassigned) as binary PLY.

open3d's PLY writer keeps no per-face properties, so this small reader/writer does: vertices with
optional colours, faces with an ``int rock_id``. MeshLab, CloudCompare and Blender open these files.
Faces of more than three corners (Blender's PLY and OBJ keep quads and n-gons) are cut into
triangles fanning from their first corner, here and in :func:`read_obj`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from .errors import MeshError

__all__ = [
    'LabelledMesh',
    'MeshError',
    'ObjFile',
    'PlyElement',
    'PlyHeader',
    'check_arrays',
    'check_ply_size',
    'eight_bit',
    'fan_triangles',
    'read_labelled_mesh',
    'read_obj',
    'read_ply_header',
    'write_labelled_mesh',
]


@dataclass
class LabelledMesh:
    """A triangle mesh whose faces carry an integer label.

    Attributes:
        vertices: Nx3 float64 vertex positions [m].
        faces: Mx3 int64 vertex indices.
        labels: M int32 face labels (rock id, 0 = ground or unassigned).
        colors: Nx3 uint8 vertex colours, or None.

    """

    vertices: npt.NDArray[np.float64]
    faces: npt.NDArray[np.int64]
    labels: npt.NDArray[np.int32]
    colors: npt.NDArray[np.uint8] | None = None


def write_labelled_mesh(path: str | Path, mesh: LabelledMesh) -> None:
    """Write ``mesh`` as binary little-endian PLY with a ``rock_id`` face property."""
    nv, nf = len(mesh.vertices), len(mesh.faces)
    if len(mesh.labels) != nf:
        raise ValueError(f'{len(mesh.labels)} labels for {nf} faces')
    lines = ['ply', 'format binary_little_endian 1.0', 'comment stockpile_ros labelled mesh']
    lines += [f'element vertex {nv}', 'property float x', 'property float y', 'property float z']
    vdesc: list[tuple[str, str]] = [('x', '<f4'), ('y', '<f4'), ('z', '<f4')]
    if mesh.colors is not None:
        lines += ['property uchar red', 'property uchar green', 'property uchar blue']
        vdesc += [('red', 'u1'), ('green', 'u1'), ('blue', 'u1')]
    lines += [
        f'element face {nf}',
        'property list uchar int vertex_indices',
        'property int rock_id',
    ]
    lines.append('end_header')
    verts = np.empty(nv, dtype=vdesc)
    for i, axis in enumerate('xyz'):
        verts[axis] = mesh.vertices[:, i]
    if mesh.colors is not None:
        for i, channel in enumerate(('red', 'green', 'blue')):
            verts[channel] = mesh.colors[:, i]
    faces = np.empty(nf, dtype=[('n', 'u1'), ('v', '<i4', (3,)), ('rock_id', '<i4')])
    faces['n'] = 3
    faces['v'] = mesh.faces
    faces['rock_id'] = mesh.labels
    with Path(path).open('wb') as out:
        out.write(('\n'.join(lines) + '\n').encode('ascii'))
        out.write(verts.tobytes())
        out.write(faces.tobytes())


_PLY_TYPES = {
    'char': 'i1', 'uchar': 'u1', 'short': 'i2', 'ushort': 'u2', 'int': 'i4', 'uint': 'u4',
    'float': 'f4', 'double': 'f8', 'int8': 'i1', 'uint8': 'u1', 'int16': 'i2', 'uint16': 'u2',
    'int32': 'i4', 'uint32': 'u4', 'float32': 'f4', 'float64': 'f8',
}  # fmt: skip
_PLY_ORDER = {'binary_little_endian': '<', 'binary_big_endian': '>', 'ascii': '='}
_INDEX_NAMES = ('vertex_indices', 'vertex_index')
# The shortest text an ASCII value can take: one digit and a separator.
_ASCII_VALUE_BYTES = 2


@dataclass
class PlyElement:
    """One ``element`` of a PLY header.

    Attributes:
        name: Element name (``vertex``, ``face``, ...).
        count: Number of items the header claims.
        properties: ``(name, numpy type)`` per scalar property; a vertex-index list appears as
            its count ``("n", type)`` followed by ``("v", type)`` for three indices.

    """

    name: str
    count: int
    properties: list[tuple[str, str]]


@dataclass
class PlyHeader:
    """A parsed PLY header.

    Attributes:
        format: ``binary_little_endian``, ``binary_big_endian`` or ``ascii``.
        elements: The elements in file order.
        body_offset: Byte offset of the data after ``end_header``.

    """

    format: str
    elements: list[PlyElement]
    body_offset: int

    def element(self, name: str) -> PlyElement | None:
        """Return the element called ``name``, or None."""
        return next((e for e in self.elements if e.name == name), None)


def _header_line(words: list[str], elements: list[PlyElement], where: str) -> None:
    """Add one ``element`` or ``property`` line to ``elements``."""
    if words[0] == 'element':
        if len(words) != 3 or not words[2].isdigit():
            raise MeshError(f'{where}: expected "element NAME COUNT"')
        elements.append(PlyElement(words[1], int(words[2]), []))
        return
    if not elements:
        raise MeshError(f'{where}: property before any element')
    props = elements[-1].properties
    if len(words) == 5 and words[1] == 'list':
        if words[2] not in _PLY_TYPES or words[3] not in _PLY_TYPES:
            raise MeshError(f'{where}: unknown list types {words[2]} {words[3]}')
        if words[4] not in _INDEX_NAMES:
            raise MeshError(f'{where}: unsupported list property {words[4]}')
        props += [('n', _PLY_TYPES[words[2]]), ('v', _PLY_TYPES[words[3]])]
    elif len(words) == 3 and words[1] in _PLY_TYPES:
        props.append((words[2], _PLY_TYPES[words[1]]))
    else:
        raise MeshError(f'{where}: expected "property TYPE NAME" or a vertex index list')


def read_ply_header(raw: bytes, source: str | Path) -> PlyHeader:
    """Parse and check the header of a PLY file held in ``raw``.

    Every line must be a known keyword with its fields; a blank line, an unknown keyword, a
    missing ``format`` or a vertex element without x, y, z is refused.

    Args:
        raw: The file's bytes (at least its header).
        source: The file, for messages.

    Returns:
        The header.

    Raises:
        MeshError: Not a PLY header this module understands; the text names the line.

    """
    if not raw.startswith(b'ply'):
        raise MeshError(f'{source}: not a PLY file (no "ply" magic)')
    match = re.search(rb'^end_header[ \t]*\r?\n', raw, re.MULTILINE)
    if match is None:
        raise MeshError(f'{source}: PLY header without "end_header"')
    try:
        text = raw[: match.start()].decode('ascii')
    except UnicodeDecodeError:
        raise MeshError(f'{source}: PLY header is not ASCII text') from None
    lines = text.splitlines()
    fmt: str | None = None
    elements: list[PlyElement] = []
    for number, line in enumerate(lines[1:], start=2):
        where = f'{source}: PLY header line {number}'
        words = line.split()
        if not words:
            raise MeshError(f'{where} is blank')
        if words[0] in ('comment', 'obj_info'):
            continue
        if words[0] == 'format':
            if len(words) != 3 or words[1] not in _PLY_ORDER or words[2] != '1.0':
                raise MeshError(f'{where}: unknown format {" ".join(words[1:])!r}')
            fmt = words[1]
        elif words[0] in ('element', 'property'):
            _header_line(words, elements, where)
        else:
            raise MeshError(f'{where}: unknown keyword {words[0][:40]!r}')
    if lines[0].strip() != 'ply' or fmt is None:
        raise MeshError(f'{source}: PLY header without "ply" and "format" lines')
    header = PlyHeader(fmt, elements, match.end())
    vertex = header.element('vertex')
    if vertex is None or not {'x', 'y', 'z'} <= {p for p, _ in vertex.properties}:
        raise MeshError(f'{source}: PLY header has no vertex element with x, y and z')
    return header


def check_ply_size(header: PlyHeader, size: int, source: str | Path) -> None:
    """Refuse a header that claims more items than ``size`` bytes can hold, before any allocation.

    Binary bodies must hold every item in full (a face at least as a triangle: a count and three
    indices); an ASCII value takes at least two bytes (a digit and a separator).

    Raises:
        MeshError: The header's counts do not fit in the file.

    """
    need = 0
    for element in header.elements:
        if header.format == 'ascii':
            values = sum(3 if p == 'v' else 1 for p, _ in element.properties)
            need += element.count * values * _ASCII_VALUE_BYTES
        else:
            need += element.count * _dtype(element, '<').itemsize
    available = size - header.body_offset
    if need > available:
        counts = ', '.join(f'{e.count} {e.name}' for e in header.elements)
        kind = 'at least ' if header.format == 'ascii' else ''
        raise MeshError(
            f'{source}: PLY header claims {counts} ({kind}{need} bytes) but the file holds '
            f'{available} bytes after the header (truncated, or the counts are wrong)'
        )


def _typed(kind: str, order: str) -> str:
    """Return a PLY property's numpy type in the file's byte order (one-byte types have none)."""
    return kind if kind.endswith('1') else order + kind


def _dtype(element: PlyElement, order: str, sides: int = 3) -> np.dtype[np.void]:
    fields: list[tuple[str, str] | tuple[str, str, tuple[int]]] = []
    for name, kind in element.properties:
        typ = _typed(kind, order)
        fields.append((name, typ, (sides,)) if name == 'v' else (name, typ))
    try:
        return np.dtype(fields)
    except (ValueError, TypeError) as exc:  # duplicate property names
        raise MeshError(f'PLY element {element.name}: {exc}') from None


def check_arrays(
    vertices: npt.NDArray[np.float64], faces: npt.NDArray[np.int64], source: str | Path
) -> None:
    """Refuse a mesh that no reader of it could use.

    That is: no vertices or faces, non-finite vertices, face indices out of range, or faces that
    are not triangles.

    Raises:
        MeshError: The first of those faults, with how many items it concerns.

    """
    if len(vertices) == 0 or len(faces) == 0:
        raise MeshError(f'{source}: mesh has {len(vertices)} vertices and {len(faces)} faces')
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise MeshError(f'{source}: faces are not triangles (shape {faces.shape})')
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise MeshError(
            f'{source}: {int(bad.sum())} of {len(vertices)} vertices are not finite '
            f'(NaN or infinite; first: vertex {first})'
        )
    out = (faces < 0) | (faces >= len(vertices))
    if out.any():
        face = int(np.flatnonzero(out.any(axis=1))[0])
        raise MeshError(
            f'{source}: {int(out.any(axis=1).sum())} faces index vertices outside 0..'
            f'{len(vertices) - 1} (first: face {face}, {faces[face].tolist()})'
        )


def fan_triangles(
    corners: npt.NDArray[np.int64], sides: npt.NDArray[np.int64], source: str | Path
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Cut polygons into triangles fanning from each one's first corner.

    Args:
        corners: Every polygon's vertex indices, one polygon after the other.
        sides: Each polygon's number of corners.
        source: The file, for messages.

    Returns:
        The triangles (Kx3) and, for each, the polygon it came from.

    Raises:
        MeshError: A polygon of fewer than three corners.

    """
    short = np.flatnonzero(sides < 3)
    if len(short):
        raise MeshError(
            f'{source}: {len(short)} faces have fewer than 3 corners (first: face '
            f'{int(short[0])}, {int(sides[short[0]])})'
        )
    if len(sides) and int(sides.max()) == 3 == int(sides.min()):
        return corners.reshape(-1, 3), np.arange(len(sides))
    start = np.cumsum(sides) - sides
    count = sides - 2
    polygon = np.repeat(np.arange(len(sides)), count)
    # The k-th triangle of a polygon takes its first corner and corners k + 1 and k + 2.
    k = np.arange(len(polygon)) - np.repeat(np.cumsum(count) - count, count)
    first = start[polygon]
    faces = np.stack([corners[first], corners[first + k + 1], corners[first + k + 2]], axis=1)
    return faces.astype(np.int64), polygon


def _ply_faces(
    raw: bytes, offset: int, element: PlyElement, order: str, source: str | Path
) -> tuple[npt.NDArray[np.void], tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]], int]:
    """Read a binary face element whose faces may have any number of corners.

    Returns:
        The element's scalar properties per face, its corners and corner counts (see
        :func:`fan_triangles`), and the offset after it.

    """
    if element.count == 0:
        empty = np.zeros(0, dtype=np.int64)
        return np.zeros(0, dtype=_dtype(element, order)), (empty, empty), offset
    # Most files hold one kind of polygon: read them all at once with the first face's count.
    count_type = _typed(dict(element.properties)['n'], order)
    first = np.frombuffer(raw, dtype=count_type, count=1, offset=offset + _prefix(element, order))
    dtype = _dtype(element, order, max(int(first[0]), 1))
    if offset + dtype.itemsize * element.count <= len(raw):
        data = np.frombuffer(raw, dtype=dtype, count=element.count, offset=offset)
        if np.all(data['n'] == first[0]):
            corners = np.asarray(data['v'], dtype=np.int64).reshape(-1)
            sides = np.asarray(data['n'], dtype=np.int64)
            return data, (corners, sides), offset + dtype.itemsize * element.count
    return _ply_mixed_faces(raw, offset, element, order, source)


def _prefix(element: PlyElement, order: str) -> int:
    """Bytes of a face's properties before its corner count."""
    size = 0
    for name, kind in element.properties:
        if name == 'n':
            return size
        size += np.dtype(_typed(kind, order)).itemsize
    return size


def _ply_mixed_faces(
    raw: bytes, offset: int, element: PlyElement, order: str, source: str | Path
) -> tuple[npt.NDArray[np.void], tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]], int]:
    """Read a face element of polygons of several sizes, one face after the other."""
    kinds = [(name, np.dtype(_typed(kind, order))) for name, kind in element.properties]
    scalars = [(name, kind) for name, kind in kinds if name not in ('n', 'v')]
    values: dict[str, list[float]] = {name: [] for name, _ in scalars}
    corners: list[npt.NDArray[np.int64]] = []
    sides = np.zeros(element.count, dtype=np.int64)
    at = offset
    try:
        for face in range(element.count):
            n = 0
            for name, kind in kinds:
                if name == 'v':
                    corners.append(np.frombuffer(raw, dtype=kind, count=n, offset=at))
                    at += kind.itemsize * n
                    continue
                value = np.frombuffer(raw, dtype=kind, count=1, offset=at)[0]
                at += kind.itemsize
                if name == 'n':
                    n = int(value)
                    sides[face] = n
                else:
                    values[name].append(value)
    except ValueError:
        raise MeshError(
            f'{source}: PLY face element ends before its {element.count} faces do (truncated)'
        ) from None
    data = np.zeros(element.count, dtype=np.dtype([(name, kind) for name, kind in scalars]))
    for name, _ in scalars:
        data[name] = values[name]
    flat = np.concatenate(corners).astype(np.int64) if corners else np.zeros(0, dtype=np.int64)
    return data, (flat, sides), at


def eight_bit(values: npt.ArrayLike) -> npt.NDArray[np.uint8]:
    """Colours as 8 bits: 0..1 floats scaled by 255, 16-bit channels shifted down."""
    v = np.asarray(values, dtype=np.float64)
    top = float(v.max()) if v.size else 0.0
    if top <= 1.0 and not np.all(v == np.round(v)):
        v = v * 255.0
    elif top > 255.0:
        v = v / 257.0
    return np.asarray(np.clip(np.round(v), 0, 255), dtype=np.uint8)


@dataclass
class ObjFile:
    """What a Wavefront OBJ file holds of a mesh or a cloud.

    Attributes:
        vertices: Nx3 positions (``v``).
        colors: Nx3 colours following the positions (:func:`eight_bit`), or None unless every
            vertex has one.
        normals: The ``vn`` normals in file order, or None.
        faces: Kx3 triangles (``f``; polygons fanned from their first corner), 0-based.

    """

    vertices: npt.NDArray[np.float64]
    colors: npt.NDArray[np.uint8] | None
    normals: npt.NDArray[np.float64] | None
    faces: npt.NDArray[np.int64]


def read_obj(path: str | Path) -> ObjFile:
    """Read the vertices, colours, normals and faces of an OBJ file.

    Groups, materials and texture coordinates are ignored; a negative index counts back from
    the last vertex read.

    Raises:
        MeshError: A face index that is not a number.
        OSError: The file cannot be read.

    """
    points: list[list[float]] = []
    colors: list[list[float]] = []
    normals: list[list[float]] = []
    corners: list[int] = []
    sides: list[int] = []
    with Path(path).open('r', errors='replace') as stream:
        for number, line in enumerate(stream, start=1):
            words = line.split()
            if not words:
                continue
            if words[0] == 'v' and len(words) >= 4:
                points.append([float(w) for w in words[1:4]])
                if len(words) >= 7:
                    colors.append([float(w) for w in words[4:7]])
            elif words[0] == 'vn' and len(words) >= 4:
                normals.append([float(w) for w in words[1:4]])
            elif words[0] == 'f':
                try:
                    face = [int(w.split('/')[0]) for w in words[1:]]
                except ValueError:
                    raise MeshError(
                        f'{path}: line {number}: a face index is not a number'
                    ) from None
                corners += [i - 1 if i > 0 else len(points) + i for i in face]
                sides.append(len(face))
    faces, _ = fan_triangles(np.asarray(corners, dtype=np.int64),
                             np.asarray(sides, dtype=np.int64), path)  # fmt: skip
    return ObjFile(
        np.asarray(points, dtype=np.float64).reshape(-1, 3),
        eight_bit(colors) if colors and len(colors) == len(points) else None,
        np.asarray(normals, dtype=np.float64) if normals else None,
        faces,
    )


def read_labelled_mesh(path: str | Path) -> LabelledMesh:
    """Read a binary PLY mesh, such as :func:`write_labelled_mesh` writes.

    Both byte orders are read; faces without a ``rock_id`` property get label 0, and faces of
    more than three corners are cut into triangles (:func:`fan_triangles`), each with its
    face's label. The header is checked against the file's size before anything is allocated,
    and the arrays with :func:`check_arrays`.

    Raises:
        MeshError: Not a binary PLY mesh, a header that does not fit the file, a face of fewer
            than three corners, or arrays :func:`check_arrays` refuses; the text names the file
            and the fault.
        OSError: The file cannot be read.

    """
    raw = Path(path).read_bytes()
    header = read_ply_header(raw, path)
    if header.format == 'ascii':
        raise MeshError(f'{path}: ASCII PLY; only binary PLY is read here')
    check_ply_size(header, len(raw), path)
    if header.element('face') is None:
        raise MeshError(f'{path}: PLY without a face element')
    order = _PLY_ORDER[header.format]
    offset = header.body_offset
    data: dict[str, npt.NDArray[np.void]] = {}
    polygons: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]] | None = None
    for element in header.elements:
        if element.name == 'face' and any(name == 'v' for name, _ in element.properties):
            data['face'], polygons, offset = _ply_faces(raw, offset, element, order, path)
            continue
        dtype = _dtype(element, order)
        data[element.name] = np.frombuffer(raw, dtype=dtype, count=element.count, offset=offset)
        offset += dtype.itemsize * element.count
    v, f = data['vertex'], data['face']
    if polygons is None:
        raise MeshError(f'{path}: PLY face element without a vertex index list')
    names = v.dtype.names or ()
    colors = None
    if {'red', 'green', 'blue'} <= set(names):
        colors = np.stack([v['red'], v['green'], v['blue']], axis=1).astype(np.uint8)
    fnames = f.dtype.names or ()
    labels = f['rock_id'] if 'rock_id' in fnames else np.zeros(len(f))
    vertices = np.stack([v['x'], v['y'], v['z']], axis=1).astype(np.float64)
    faces, polygon = fan_triangles(*polygons, path)
    labels = np.asarray(labels)[polygon]
    check_arrays(vertices, faces, path)
    return LabelledMesh(
        vertices=vertices,
        faces=faces,
        labels=np.asarray(labels, dtype=np.int32),
        colors=colors,
    )
