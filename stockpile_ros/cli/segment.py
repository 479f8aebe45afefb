"""``stockpile segment``: rocks out of a stockpile mesh, with the result folder."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..artefacts import MeshInfo, ScaleRecord, load
from ..errors import StockpileError
from ..meshcheck import UNITS, read_mesh
from ..segment.pipeline import analyse_mesh
from ..segment.provenance import Provenance
from ..segment.qa import report_options
from ..segment.report import write_result_folder
from ..settings import class_spec, defaults, write_effective
from .parameters import Alias, add_parameter_arguments, settings_from_args

__all__ = ['DESCRIPTION', 'add_arguments', 'run']

DESCRIPTION = """Segment a stockpile mesh (metric, z up, ground at z = 0) into rocks with the
curvature search of the paper (Eq. 2), measure each rock (a, b, c, ESD, volume, mass,
sphericity...) and the pile's gradation, optionally check it against a riprap class, and write the
result folder:
report.json, segments.ply, rocks.csv, gradation.png, render.png, keyframe.png (a keyframe photo
with the rocks outlined, when the keyframes/ folder of the work folder is beside the mesh's
folder), index.html and report.pdf. The verdict against a class is PASS, FAIL or UNDECIDED (a
confidence interval straddles a limit); without a metric scale no class is checked.

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
)  # fmt: skip


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add this subcommand's arguments."""
    parser.add_argument('mesh', type=Path, help='mesh PLY (e.g. RECON/mesh/mesh.ply)')
    parser.add_argument('--out', type=Path, required=True, help='result folder to write')
    parser.add_argument(
        '--mesh-info', type=Path, help='mesh.json of the reconstruction (scale, keyframes)'
    )
    parser.add_argument(
        '--units',
        choices=list(UNITS),
        help='length unit of the mesh coordinates, scaled to metres (default: metres; a mesh '
        'whose size is implausible in metres is refused unless its units are given). Without '
        '--mesh-info the result is in model units (no metres, no class verdict) unless the '
        'units are given here (scale method "given")',
    )
    add_parameter_arguments(parser, _ALIASES)


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    settings = settings_from_args(args)
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
    spec = class_spec(settings)
    options = report_options(settings.values)
    analysis = analyse_mesh(
        mesh.vertices, mesh.faces, mesh.colors,
        seg_params=settings.segment, measure_params=settings.measure,
        spec=spec, mesh_info=info, source=str(args.mesh), report_options=options,
    )  # fmt: skip
    analysis.report['mesh']['check'] = check.as_dict()
    analysis.report['warnings'][:0] = check.warnings
    provenance = Provenance.for_input(args.mesh, settings.values, defaults())
    keyframes = args.mesh.resolve().parent.parent / 'keyframes'
    write_result_folder(args.out, analysis, provenance, options, keyframes)
    write_effective(settings, args.out)
    g = analysis.report['gradation']
    metric = analysis.report['units'] != 'model'
    unit = 'm' if metric else 'model units'
    d50 = 'undefined' if g['d50'] is None else f'{g["d50"]:.3f} {unit}'
    mass = f', total mass {g["total_mass"]:.1f} kg' if metric else ''
    print(f'{len(analysis.rocks)} rocks, D50 {d50}{mass} -> {args.out}')
    if g['spec']['class'] is not None:
        reasons = '; '.join(g['spec']['reasons'])
        print(
            f'class {g["spec"]["class"]}: {g["spec"]["verdict"]}{": " if reasons else ""}{reasons}'
        )
    for text in analysis.report['warnings']:
        print(f'stockpile segment: warning: {text}', file=sys.stderr)
    return 0
