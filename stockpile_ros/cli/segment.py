"""``stockpile segment``: rocks out of a stockpile mesh or point cloud, with the result folder."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..artefacts import MeshInfo, ScaleMethod, ScaleRecord, SimilarityRecord, load
from ..cloud import (
    cloud_segment_params,
    is_mesh_file,
    level_transform,
    mesh_cloud,
    parse_up,
    read_cloud,
    trend_up,
)
from ..errors import StockpileError
from ..meshcheck import UNITS, MeshCheck, check_mesh, read_mesh
from ..meshio import LabelledMesh
from ..segment.adjacency import FaceGeometry, face_geometry
from ..segment.params import median_edge
from ..segment.pipeline import analyse_mesh
from ..segment.provenance import Provenance
from ..segment.qa import report_options
from ..segment.report import write_result_folder
from ..settings import Settings, class_spec, defaults, smallest_rock_asked, write_effective
from .parameters import Alias, add_parameter_arguments, settings_from_args

__all__ = ['DESCRIPTION', 'add_arguments', 'run']

DESCRIPTION = """Segment a stockpile mesh (metric, z up, ground at z = 0) or a point cloud into
rocks with the curvature search of the paper (Eq. 2), measure each rock (a, b, c, ESD, volume, mass,
sphericity...) and the pile's gradation, optionally check it against a riprap class, and write the
result folder:
report.json, segments.ply, rocks.csv, gradation.png, render.png, keyframe.png (a keyframe photo
with the rocks outlined, when the keyframes/ folder of the work folder is beside the mesh's
folder), index.html and report.pdf. The verdict against a class is PASS, FAIL or UNDECIDED (a
confidence interval straddles a limit); without a metric scale no class is checked.

Inputs: a mesh (PLY or OBJ with faces: levelled like a cloud unless it is in the stockpile
frame already, as this project's are, or --mesh-info gives its frame) or a point cloud (PLY
without faces, OBJ vertices, LAS/LAZ, XYZ/CSV/TXT columns x y z [nx ny nz] [r g b] with an
optional header), with or without normals and colours. A cloud is levelled (up from --up, else
the normal of its robust trend plane: no bare ground is needed), its normals estimated where
missing and turned to the side the cloud is seen from, and Poisson-meshed at a depth whose
finest cell is about its resolution: the point spacing, or three times the points' noise about
their surface where that is longer (cloud.* parameters); its smallest rock is
cloud.min_rock_spacings resolutions (in place of the 20-edge floor below, which is what a mesh
from photos resolves). Units: LAS/LAZ coordinates
are taken as metres (scale method "input units"), other files as model units (no metres, no
verdict) unless --units names their unit (scale method "given").

Modes: "paper" is the published rule (t = 0.7, face normals, no clean-up); "default" keeps the
ground and the valleys at the scale of the smallest rock of interest out of the search, uses
t = 0.93, seeds from convex faces, merges fragments smaller than a share of the smallest rock of
interest (its full plan area), hands the valley faces back to the rocks on either side and joins
neighbouring regions whose union is convex across their shared border. Every length is in the
mesh's median edge or in units of segment.min_rock_b (metres; by default half the checked class's
smallest D15, else 20 median edges, and never under 20 edges: the mesh cannot resolve less), with
the valley and split radii never under 4 and 8 edges (the reconstruction's noise sits below), so a
pile of gravel and one of riprap are cut by the same rules.

Class tables: config/riprap_classes.yaml (NCHRP 568 classes I-X, by mass; the default) and
config/fp14_riprap_classes.yaml (FHWA FP-14 classes 1-8, by count).

Parameters are those of the segmentation node (config/stockpile.yaml): --params FILE reads a
parameters file, --set NAME=VALUE sets one (e.g. --set measure.specific_gravity=2.7 --set
measure.completion=hull). A segment value set explicitly wins over the preset of the mode. Every
value is checked before the mesh is read, and the values used are written to OUT/params.yaml."""

# The convenience flags: each sets one table key, and only when it is given.
_ALIASES = (
    Alias('--mode', 'segment.mode', 'preset of the segment values not set explicitly'),
    Alias('--threshold', 'segment.threshold', 't of Eq. 2 (paper 0.7)', metavar='T'),
    Alias('--spec-class', 'gradation.spec_class', 'riprap class to check, e.g. III',
          metavar='CLASS'),
    Alias('--class-table', 'gradation.class_table',
          'class table YAML (default config/riprap_classes.yaml)', metavar='FILE'),
    Alias('--up', 'cloud.up', 'up in the input frame, x,y,z, or fit (the robust trend plane); '
          'a cloud is always levelled, a mesh unless it is in the stockpile frame already',
          metavar='X,Y,Z|fit'),
)  # fmt: skip


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add this subcommand's arguments."""
    parser.add_argument('mesh', type=Path, metavar='INPUT',
                        help='mesh (e.g. RECON/mesh/mesh.ply, or OBJ) or point cloud (PLY, '
                        'LAS, LAZ, XYZ, CSV, TXT)')  # fmt: skip
    parser.add_argument('--out', type=Path, required=True, help='result folder to write')
    parser.add_argument(
        '--mesh-info', type=Path, help='mesh.json of the reconstruction (scale, keyframes)'
    )
    parser.add_argument(
        '--units',
        choices=list(UNITS),
        help='length unit of the input coordinates, scaled to metres (default: metres; a mesh '
        'whose size is implausible in metres is refused unless its units are given). Without '
        '--mesh-info the result is in model units (no metres, no class verdict) unless the '
        'units are given here (scale method "given") or the input is LAS/LAZ (survey '
        'coordinates, taken as metres: scale method "input units")',
    )
    add_parameter_arguments(parser, _ALIASES)


def _from_cloud(
    args: argparse.Namespace, settings: Settings
) -> tuple[LabelledMesh, MeshCheck, MeshInfo]:
    """Read and mesh a point cloud file; returns the mesh, its check and what it is."""
    cloud = read_cloud(args.mesh)
    method: ScaleMethod
    if args.units is not None:
        metres, method = UNITS[args.units], 'given'
    elif cloud.format in ('las', 'laz'):
        # A survey format: its coordinates are in the units of its reference system.
        metres, method = 1.0, 'input units'
    else:
        metres, method = 1.0, 'none'
    mesh, info = mesh_cloud(cloud, settings.cloud, settings.recon.poisson, metres, method,
                            min_rock_b=smallest_rock_asked(settings))  # fmt: skip
    mesh, check = check_mesh(mesh, args.mesh)
    c, p = info.cloud or {}, info.poisson
    unit = 'm' if method != 'none' else 'model units'
    thinned = ''
    if c['thinned_to']:
        thinned = (f' of {c["points_read"]} (thinned to {c["thinned_to"]:.3g} {unit}, all the '
                   'smallest rock of interest needs)')  # fmt: skip
    print(f'cloud: {c["points_used"]} points{thinned}, spacing {c["spacing"]:.3g} {unit}, up '
          f'{c["up"]["tilt_deg"]:.1f} deg from the input z, Poisson depth {p["depth"]} -> '
          f'{p["faces"]} faces')  # fmt: skip
    if method == 'none':
        print('stockpile segment: note: no --units: sizes in model units (pass --units m if the '
              'coordinates are metres)', file=sys.stderr)  # fmt: skip
    elif not check.plausible:
        raise StockpileError(f'{check.warnings[-1]}; pass the right --units')
    return mesh, check, info


def _ground_share(g: FaceGeometry, settings: Settings, edge: float) -> float:
    """Share of the surface the segmentation would take as ground, with z = 0 where it is."""
    p = settings.segment
    ground = (np.abs(g.centroids[:, 2]) < p.ground_tolerance_edges * edge) & (
        g.normals[:, 2] >= p.ground_min_nz
    )
    return float(g.areas[ground].sum() / max(float(g.areas.sum()), 1e-300))


def _level(mesh: LabelledMesh, settings: Settings, info: MeshInfo) -> bool:
    """Level a foreign mesh as a cloud would be (:mod:`stockpile_ros.cloud.level`), in place.

    Without ``--up`` a mesh already in the stockpile frame is kept as it is: one whose levelled
    heights are within one median edge of its own everywhere, as this project's meshes are, or on
    which its own z = 0 takes at least as much of the surface as ground as the fitted plane does
    (the segmentation's ground rule): on a cloud route's mesh of a large pile over little ground
    (bench_cloud's survey, 44 % ground) the trend plane of the mesh's evenly spread vertices was
    2 degrees off and took 7 %. The segmentation takes z = 0 as the ground, so a mesh in another
    tool's frame (survey heights, a tilt, another axis up) would otherwise give its ground as
    rocks, and sizes that look right.

    Returns:
        Whether the mesh was moved.

    """
    v, f = mesh.vertices, mesh.faces
    given = face_geometry(v, f)
    up, why = parse_up(settings.cloud.up), 'given'
    if up is None:
        # The winding says which side was seen; where it is mixed, the bulge does.
        up, why = trend_up(v, given.normals)
    sim, plane = level_transform(v, up, 1.0, settings.cloud.ground_percentile)
    levelled = sim.apply(v)
    moved = float(np.abs(levelled[:, 2] - v[:, 2]).max())
    edge = median_edge(v, f)
    if 'cloud.up' not in settings.explicit and (
        moved <= edge
        or _ground_share(given, settings, edge)
        >= _ground_share(face_geometry(levelled, f), settings, edge)
    ):
        return False
    tilt = float(np.degrees(np.arccos(np.clip(up[2], -1.0, 1.0))))
    print(f'mesh: levelled into the stockpile frame: up {tilt:.1f} deg from the input z ({why}), '
          f'heights moved by up to {moved:.3g} m')  # fmt: skip
    mesh.vertices = levelled
    info.ground_plane_model = [float(x) for x in plane]
    info.model_to_stockpile = SimilarityRecord.of(sim)
    return True


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    settings = settings_from_args(args)
    info: MeshInfo | None
    levelled = False
    mesh_file = is_mesh_file(args.mesh)
    # Another tool's mesh: no --mesh-info says what made it.
    foreign = mesh_file and args.mesh_info is None
    if not mesh_file:
        if args.mesh_info is not None:
            raise StockpileError('--mesh-info goes with a mesh; a point cloud is meshed here')
        mesh, check, info = _from_cloud(args, settings)
    else:
        mesh, check = read_mesh(args.mesh, args.units or 'm')
        if not check.plausible and args.units is None:
            hint = f' --units {check.likely_units}' if check.likely_units else ' --units'
            raise StockpileError(
                f'{check.warnings[-1]}; pass{hint} to scale it, or --units m to keep it as it is'
            )
        info = None if args.mesh_info is None else load(MeshInfo, args.mesh_info)
        if info is None and args.units is not None:
            # The user vouches for the mesh's units: metric, though no target or odometry says so.
            info = MeshInfo(ScaleRecord('given', UNITS[args.units]), units='m')
        if args.mesh_info is None:
            levelling = info or MeshInfo()
            levelled = _level(mesh, settings, levelling)
            info = levelling if levelled else info
        elif 'cloud.up' in settings.explicit:
            raise StockpileError('--up levels a foreign mesh; this one is levelled already '
                                 '(its --mesh-info has model_to_stockpile)')  # fmt: skip
    spec = class_spec(settings)
    options = report_options(settings.values)
    analysis = analyse_mesh(
        mesh.vertices, mesh.faces, mesh.colors,
        seg_params=cloud_segment_params(settings.segment, info, settings.explicit),
        measure_params=settings.measure,
        spec=spec, mesh_info=info, source=str(args.mesh), report_options=options,
        search_floor=foreign and 'segment.min_rock_edges' not in settings.explicit,
    )  # fmt: skip
    report = analysis.report
    report.mesh.check = check
    if info is not None and (info.cloud is not None or levelled):
        # How a cloud or a foreign mesh was levelled and meshed: the way back to its frame.
        report.mesh.cloud = info.cloud
        report.mesh.poisson = info.poisson or None
        report.mesh.model_to_stockpile = info.model_to_stockpile
    report.warnings[:0] = check.warnings
    provenance = Provenance.for_input(args.mesh, settings.values, defaults())
    keyframes = args.mesh.resolve().parent.parent / 'keyframes'
    write_result_folder(args.out, analysis, provenance, options, keyframes)
    write_effective(settings, args.out)
    g = report.gradation
    unit = 'm' if report.metric else 'model units'
    d50 = 'undefined' if g.d50 is None else f'{g.d50:.3f} {unit}'
    mass = f', total mass {g.total_mass:.1f} kg' if g.total_mass is not None else ''
    print(f'{len(analysis.rocks)} rocks, D50 {d50}{mass} -> {args.out}')
    if g.spec.class_name is not None:
        reasons = '; '.join(g.spec.reasons)
        print(f'class {g.spec.class_name}: {g.spec.verdict}{": " if reasons else ""}{reasons}')
    for text in report.warnings:
        print(f'stockpile segment: warning: {text}', file=sys.stderr)
    return 0
