"""One check for every mesh a command reads: structure, degenerate and duplicate faces, scale.

:func:`read_mesh` reads a mesh file (binary PLY and OBJ with this package's readers; ASCII PLY,
STL and OFF through open3d, PLY headers checked against the file size first) and hands it to
:func:`check_mesh`, which refuses what no stage can use and cleans what would mislead one:

- refused (:class:`~stockpile_ros.errors.MeshError`): no vertices or faces, non-finite vertices,
  face indices out of range, nothing left once degenerate and duplicate faces are dropped;
- joined: in a mesh with more vertices than faces (stored face by face, as STL is), every
  face's corners are pointed at the first vertex at their positions, so that faces border
  each other;
- dropped and counted: faces that repeat a vertex index or have zero area (their normals are
  undefined and their zero-length edges make edge-relative scales zero), and faces over the same
  three vertices as an earlier face, in any order (a tripled surface would be three rocks deep);
- flagged: a size implausible for a stockpile in the stated units, with the unit it most likely
  is in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .errors import MeshError, reading
from .meshio import (
    LabelledMesh,
    check_arrays,
    check_ply_size,
    read_labelled_mesh,
    read_obj,
    read_ply_header,
)

__all__ = [
    'BROKEN_SHARE',
    'PLAUSIBLE_EDGE_M',
    'PLAUSIBLE_EXTENT_M',
    'UNITS',
    'MeshCheck',
    'check_mesh',
    'degenerate_faces',
    'duplicate_faces',
    'join_vertices',
    'read_mesh',
]

UNITS: dict[str, float] = {
    'm': 1.0,
    'cm': 0.01,
    'mm': 0.001,
    'km': 1000.0,
    'in': 0.0254,
    'ft': 0.3048,
}
"""Metres per unit of each length unit a mesh may be given in."""

_UNIT_NAMES = {
    'm': 'metres',
    'cm': 'centimetres',
    'mm': 'millimetres',
    'km': 'kilometres (or scaled by 1/1000)',
    'in': 'inches',
    'ft': 'feet',
}

PLAUSIBLE_EXTENT_M = (0.01, 1000.0)
"""Longest side of a stockpile's bounding box [m]: from a handful of pebbles to a mine's pile.

This is a check of the units, not a rule of measurement, so it is stated in metres.
"""

PLAUSIBLE_EDGE_M = (1e-5, 1.0)
"""Median edge length of a stockpile mesh [m]: finer than 10 µm or coarser than a metre is a mesh
in other units (a metre-edged mesh still resolves a boulder of a few metres)."""

BROKEN_SHARE = 0.25
"""Share of a mesh's faces of zero area over three distinct vertices from which it is refused as
no surface (faces that repeat a vertex index are records to drop, however many). A mesher leaves
a few (slivers where its surface meets itself: none on this project's meshes); a quarter or more
is a surface whose vertices fell onto each other, as a tool computing in single precision far
from the origin leaves them: open3d's Poisson of bench/bench_cloud.py's gravel bar in
coordinates 5e5 m east and 5e6 m north gave 272k of 346k faces of zero area, its vertices on
steps of 3.1 cm, and the bar (229 rocks of D50 0.19 m from the cloud) read as 7 rocks of D50
0.61 m."""

# A face is of zero area when its height is within float64 rounding of nothing, relative to its
# longest edge: scale-free, so the same faces are dropped whatever the units.
_ZERO_HEIGHT = 1e-12
# What a unit is judged against when several would make a mesh plausible: piles scanned from a
# cart are a few metres across, and their Poisson meshes have edges of a few millimetres.
_TYPICAL_EXTENT_M = 2.0
_TYPICAL_EDGE_M = 0.005


@dataclass
class MeshCheck:
    """What :func:`check_mesh` found and did.

    Attributes:
        source: The mesh, for messages.
        vertices: Vertices of the mesh.
        faces_read: Faces as read.
        degenerate_faces: Faces dropped for a repeated vertex index or zero area.
        duplicate_faces: Faces dropped for the vertex set of an earlier face.
        faces_kept: Faces left after the drops.
        units: Units the mesh was taken to be in.
        metres_per_unit: Scale applied to the vertices to give metres.
        extent_m: Longest side of the bounding box of the kept faces [m].
        median_edge_m: Median edge length of the kept faces [m].
        plausible: Whether extent and median edge are plausible for a stockpile.
        likely_units: When not plausible, the unit that would make it so (None if none does).
        warnings: One sentence per finding worth the user's attention.

    """

    source: str
    vertices: int
    faces_read: int
    degenerate_faces: int
    duplicate_faces: int
    faces_kept: int
    units: str
    metres_per_unit: float
    extent_m: float
    median_edge_m: float
    plausible: bool
    likely_units: str | None
    warnings: list[str] = field(default_factory=list)


def degenerate_faces(
    vertices: npt.NDArray[np.float64], faces: npt.NDArray[np.int64]
) -> npt.NDArray[np.bool_]:
    """Mask of faces with a repeated vertex index or zero area."""
    f0, f1, f2 = faces[:, 0], faces[:, 1], faces[:, 2]
    repeated = (f0 == f1) | (f1 == f2) | (f0 == f2)
    p0, p1, p2 = vertices[f0], vertices[f1], vertices[f2]
    twice_area = np.linalg.norm(np.cross(p1 - p0, p2 - p0), axis=1)
    longest = np.max([np.einsum('ij,ij->i', d, d) for d in (p1 - p0, p2 - p1, p0 - p2)], axis=0)
    return np.asarray(repeated | (twice_area <= _ZERO_HEIGHT * longest), dtype=bool)


def join_vertices(
    vertices: npt.NDArray[np.float64], faces: npt.NDArray[np.int64]
) -> tuple[npt.NDArray[np.int64], int]:
    """Point each face's corners at the first vertex at their positions (exactly equal).

    Returns:
        The faces so pointed, and how many of the vertices they used before are no longer used
        (the vertices themselves are kept, so vertex-indexed data stays aligned).

    """
    _, first, inverse = np.unique(vertices, axis=0, return_index=True, return_inverse=True)
    to = np.asarray(first[inverse.ravel()], dtype=np.int64)
    used = np.unique(faces)
    return to[faces], int(np.count_nonzero(to[used] != used))


def duplicate_faces(faces: npt.NDArray[np.int64]) -> npt.NDArray[np.bool_]:
    """Mask of faces over the three vertices of an earlier face (in any order)."""
    repeated = np.ones(len(faces), dtype=bool)
    repeated[_first_of_each_set(faces)] = False
    return repeated


def _first_of_each_set(faces: npt.NDArray[np.int64]) -> npt.NDArray[np.intp]:
    """Return the indices, in file order, of the first face over each set of three vertices."""
    if not len(faces):
        return np.zeros(0, dtype=np.intp)
    ordered = np.sort(faces, axis=1)
    # Sorted on two integer keys (np.unique over rows is several times slower); the sort is
    # stable, so each set's first face in the file starts its run.
    pair = ordered[:, 0] * (int(ordered[:, 1].max()) + 1) + ordered[:, 1]
    order = np.lexsort((ordered[:, 2], pair))
    pair, last = pair[order], ordered[order, 2]
    start = np.ones(len(order), dtype=bool)
    start[1:] = (pair[1:] != pair[:-1]) | (last[1:] != last[:-1])
    return np.sort(order[start])


def _plausible(extent_m: float, edge_m: float) -> bool:
    lo, hi = PLAUSIBLE_EXTENT_M
    elo, ehi = PLAUSIBLE_EDGE_M
    return lo <= extent_m <= hi and elo <= edge_m <= ehi


def _likely_units(extent_m: float, edge_m: float, metres_per_unit: float) -> str | None:
    """Return the unit that makes the mesh plausible and nearest a typical pile's mesh."""
    extent, edge = extent_m / metres_per_unit, edge_m / metres_per_unit
    fits = [u for u, s in UNITS.items() if _plausible(extent * s, edge * s)]
    if not fits:
        return None

    def distance(unit: str) -> float:  # in orders of magnitude, extent and edge together
        scale = UNITS[unit]
        return abs(math.log(extent * scale / _TYPICAL_EXTENT_M)) + abs(
            math.log(edge * scale / _TYPICAL_EDGE_M)
        )

    return min(fits, key=distance)


def check_mesh(
    mesh: LabelledMesh, source: str | Path, units: str = 'm'
) -> tuple[LabelledMesh, MeshCheck]:
    """Validate a mesh, drop its degenerate and duplicate faces, scale it to metres.

    Args:
        mesh: The mesh as read, in ``units``.
        source: The file, for messages.
        units: A key of :data:`UNITS`: what the vertex coordinates are in.

    Returns:
        The mesh in metres with the kept faces (their labels with them; vertices are kept even
        when no face uses them, so vertex-indexed data stays aligned), and what was found.

    Raises:
        MeshError: Unknown units, a mesh :func:`~stockpile_ros.meshio.check_arrays` refuses, or
            ``BROKEN_SHARE`` of its faces or more of zero area over three vertices.

    """
    if units not in UNITS:
        raise MeshError(f'unknown units {units!r} (known: {", ".join(UNITS)})')
    scale = UNITS[units]
    vertices = np.asarray(mesh.vertices, dtype=np.float64) * scale
    faces = np.asarray(mesh.faces, dtype=np.int64)
    check_arrays(vertices, faces, source)
    joined = 0
    if len(vertices) > len(faces):
        # More vertices than faces: stored face by face (STL), with no corner shared. Each
        # face's corners go to the first vertex at their positions, or no face would border
        # another and every face would be a region of its own.
        faces, joined = join_vertices(vertices, faces)
    degenerate = degenerate_faces(vertices, faces)
    kept = np.flatnonzero(~degenerate)
    unique = kept[~duplicate_faces(faces[kept])]
    duplicates = len(kept) - len(unique)
    if len(unique) == 0:
        raise MeshError(
            f'{source}: all {len(faces)} faces are degenerate (repeated vertex or zero '
            f'area){_single_precision(vertices, faces)}'
        )
    # Faces that repeat a vertex index are records to drop; zero area over three vertices is
    # geometry that collapsed.
    distinct = (
        (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    )
    collapsed = int(np.count_nonzero(degenerate & distinct))
    if collapsed >= BROKEN_SHARE * len(faces):
        raise MeshError(
            f'{source}: {collapsed} of {len(faces)} faces have zero area over three vertices, '
            f'which fell onto each other: not a surface to measure'
            f'{_single_precision(vertices, faces)}'
        )
    faces, labels = faces[unique], np.asarray(mesh.labels)[unique]
    used = vertices[np.unique(faces)]
    extent = float(np.max(used.max(axis=0) - used.min(axis=0)))
    edge = float(
        np.median(np.linalg.norm(vertices[faces] - vertices[np.roll(faces, 1, 1)], axis=2))
    )
    plausible = _plausible(extent, edge)
    check = MeshCheck(
        str(source), len(vertices), len(mesh.faces), int(degenerate.sum()), duplicates,
        len(unique), units, scale, extent, edge, plausible,
        None if plausible else _likely_units(extent, edge, scale),
    )  # fmt: skip
    if joined:
        check.warnings.append(
            f'{joined} vertices joined to the vertex before them at the same position (a mesh '
            'stored face by face, as STL is)'
        )
    if check.degenerate_faces:
        check.warnings.append(
            f'{check.degenerate_faces} degenerate faces dropped (repeated vertex or zero area)'
        )
    if duplicates:
        check.warnings.append(
            f'{duplicates} duplicate faces dropped (the vertices of an earlier face)'
        )
    if not plausible:
        likely = (
            f'it looks like {_UNIT_NAMES[check.likely_units]}'
            if check.likely_units
            else 'no length unit makes it plausible'
        )
        check.warnings.append(
            f'implausible size for a stockpile in {_UNIT_NAMES[units]}: {extent:.4g} m across '
            f'with a median edge of {edge:.3g} m (expected {PLAUSIBLE_EXTENT_M[0]:g}-'
            f'{PLAUSIBLE_EXTENT_M[1]:g} m across, edges {PLAUSIBLE_EDGE_M[0]:g}-'
            f'{PLAUSIBLE_EDGE_M[1]:g} m); {likely}'
        )
    colors = mesh.colors
    return LabelledMesh(vertices, faces, labels.astype(np.int32), colors), check


def _single_precision(vertices: npt.NDArray[np.float64], faces: npt.NDArray[np.int64]) -> str:
    """Say so where the vertices are single-precision numbers too large for the mesh's detail.

    Single precision holds 24 bits: at 5e5 m its steps are 3.1 cm. Named where every coordinate
    is a single-precision number and the step at the largest is over a millionth of the extent
    (a double-precision tool's coordinates are not all single-precision numbers).
    """
    used = vertices[np.unique(faces)]
    if not np.array_equal(used.astype(np.float32).astype(np.float64), used):
        return ''
    big = float(np.abs(used).max())
    step = float(np.spacing(np.float32(big)))
    extent = float(np.max(used.max(axis=0) - used.min(axis=0)))
    if step <= 1e-6 * extent:
        return ''
    return (
        f'; its coordinates are single-precision numbers as large as {big:.4g}, on steps of '
        f'{step:.3g} there: the tool that made it computed far from the origin (geographic '
        "coordinates). Subtract the cloud's smallest coordinates before meshing it, or give the "
        'cloud itself'
    )


def _read_with_open3d(path: Path) -> LabelledMesh:
    import open3d

    o3d: Any = open3d
    mesh = o3d.io.read_triangle_mesh(str(path))
    faces = np.asarray(mesh.triangles, dtype=np.int64)
    if len(faces) == 0:
        raise MeshError(f'{path}: not a triangle mesh open3d or stockpile_ros can read')
    colors = None
    if mesh.has_vertex_colors():
        colors = (np.clip(np.asarray(mesh.vertex_colors), 0, 1) * 255).round().astype(np.uint8)
    return LabelledMesh(np.asarray(mesh.vertices, dtype=np.float64), faces,
                        np.zeros(len(faces), dtype=np.int32), colors)  # fmt: skip


def read_mesh(path: str | Path, units: str = 'm') -> tuple[LabelledMesh, MeshCheck]:
    """Read a mesh file and :func:`check_mesh` it.

    Binary PLY goes through :func:`~stockpile_ros.meshio.read_labelled_mesh` (labels kept) and
    OBJ through :func:`~stockpile_ros.meshio.read_obj` (faces of more than three corners cut
    into triangles by both); ASCII PLY has its header checked against the file size before
    open3d reads it; STL and OFF are read by open3d.

    Args:
        path: The mesh file.
        units: What its coordinates are in (a key of :data:`UNITS`).

    Returns:
        The checked mesh in metres and the check.

    Raises:
        MeshError: The file is missing, unreadable or malformed, or the mesh is refused.

    """
    path = Path(path)
    with reading(path, 'mesh file'), path.open('rb') as stream:
        head = stream.read(3)
        if head == b'ply':
            raw = head + stream.read()
            header = read_ply_header(raw, path)
            check_ply_size(header, len(raw), path)
            del raw
            mesh = _read_with_open3d(path) if header.format == 'ascii' else read_labelled_mesh(path)
        elif path.suffix.lower() == '.obj':
            obj = read_obj(path)
            faces = obj.faces
            mesh = LabelledMesh(
                obj.vertices, faces, np.zeros(len(faces), dtype=np.int32), obj.colors
            )
        else:
            mesh = _read_with_open3d(path)
    return check_mesh(mesh, path, units)
