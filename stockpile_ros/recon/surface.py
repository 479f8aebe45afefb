"""Screened Poisson surface of the oriented dense cloud, trimmed to what the cameras saw.

Poisson closes the surface everywhere, inventing smooth "bubbles" where no point constrains it.
Those parts are removed twice over: vertices whose Poisson density (the number of samples that
supported them) is in the lowest quantile, and vertices farther from every input point than a few
point spacings. The mesh is cropped to the points' bounding box (plus a margin) and can be
simplified to a face budget.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
import numpy.typing as npt
import open3d as o3d

from ..meshcheck import degenerate_faces, duplicate_faces
from ..ranges import Range

__all__ = ['PoissonOptions', 'poisson_surface']


@dataclass(frozen=True)
class PoissonOptions:
    """Tuning of :func:`poisson_surface`.

    Attributes:
        depth: Octree depth of the Poisson solve (9 or 10 for a pile).
        density_quantile: Share of vertices with the lowest density removed.
        max_distance: Vertices farther than this many median point spacings from every point
            are removed (0 disables; a point cloud's route uses cloud.trim_spacings).
        margin: Crop box margin as a share of the points' bounding box diagonal.
        target_faces: Quadric simplification to this many faces (0 keeps them all).
        threads: Threads of the Poisson solve (0: all cores). Open3D's parallel solve is not
            repeatable: vertices move by about 1e-7 m from run to run, enough to tip a
            segmentation test (two replays of the demo gave 14 and 15 rocks, and class I PASS
            and FAIL). One thread gives the same mesh every time, at 1.3-1.5x the solve time.

    """

    depth: Annotated[int, Range(4, 14)] = 9
    density_quantile: Annotated[float, Range(0.0, 0.9)] = 0.02
    max_distance: Annotated[float, Range(0.0, 1000.0)] = 4.0
    margin: Annotated[float, Range(0.0, 1.0)] = 0.02
    target_faces: Annotated[int, Range(0, 100_000_000)] = 0
    threads: Annotated[int, Range(0, 1024)] = 1


def poisson_surface(
    points: npt.NDArray[np.float64],
    normals: npt.NDArray[np.float64],
    colors: npt.NDArray[np.float64] | None,
    options: PoissonOptions,
) -> tuple[o3d.geometry.TriangleMesh, dict[str, Any]]:
    """Poisson mesh of an oriented cloud, trimmed and cropped.

    Args:
        points: Nx3 positions.
        normals: Nx3 unit normals pointing out of the surface (towards the cameras).
        colors: Nx3 colours in [0, 1] or None.
        options: Tuning.

    Returns:
        The mesh and a record of what was done (for ``mesh.json``).

    """
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud.normals = o3d.utility.Vector3dVector(normals)
    if colors is not None:
        cloud.colors = o3d.utility.Vector3dVector(colors)
    mesh, dens = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
        cloud, depth=options.depth, n_threads=options.threads or -1
    )
    densities = np.asarray(dens)
    faces_raw = len(mesh.triangles)
    drop = densities < np.quantile(densities, options.density_quantile)

    spacing = float(np.median(np.asarray(cloud.compute_nearest_neighbor_distance())))
    if options.max_distance > 0:
        verts = o3d.geometry.PointCloud(mesh.vertices)
        far = np.asarray(verts.compute_point_cloud_distance(cloud))
        drop |= far > options.max_distance * spacing
    # The crop to the points' box goes into the same mask: open3d's crop of a mesh takes as long
    # as the rest of the trimming together.
    lo, hi = points.min(axis=0), points.max(axis=0)
    pad = options.margin * float(np.linalg.norm(hi - lo))
    position = np.asarray(mesh.vertices)
    drop |= np.any((position < lo - pad) | (position > hi + pad), axis=1)
    mesh.remove_vertices_by_mask(drop)
    # Zero-area and repeated faces too, by the rules a mesh read from a file is checked with:
    # our own mesh should not be warned about (a cloud's trimmed surface had 140 repeated faces).
    triangles = np.asarray(mesh.triangles, dtype=np.int64)
    bad = degenerate_faces(np.asarray(mesh.vertices), triangles) | duplicate_faces(triangles)
    mesh.remove_triangles_by_mask(bad.tolist())
    mesh.remove_unreferenced_vertices()
    if 0 < options.target_faces < len(mesh.triangles):
        mesh = mesh.simplify_quadric_decimation(options.target_faces)
    mesh.compute_vertex_normals()
    info: dict[str, Any] = {
        'depth': options.depth,
        'density_quantile': options.density_quantile,
        'max_distance_spacings': options.max_distance,
        'point_spacing': spacing,
        'faces_before_trimming': faces_raw,
        'faces': len(mesh.triangles),
        'vertices': len(mesh.vertices),
        'target_faces': options.target_faces,
    }
    return mesh, info
