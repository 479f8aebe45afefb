"""A survey cloud of 100k points and more from file to report: how long it takes, and how well.

A simulated survey (``stockpile_ros.tools.sim.survey``: the simulator's pile of 220 rocks of 10-35
cm sampled as a terrestrial scanner would, about 135k points at 7.5 mm, 2 mm range noise, tilted 10
degrees and offset as georeferenced coordinates are) is written as binary PLY, ASCII XYZ and LAZ;
each goes through ``stockpile segment FILE --units m`` (LAZ without --units: survey units) in this
process. Printed per file: seconds from file to result folder, the reading and meshing part of it
(measured again on its own), rocks found against the truth, the median b error and the D50 error
(by mass, against every true rock), then the smallest rock of interest the run segmented for
(``floor``) and the recall and precision over the visible rocks at least that large (smaller
rocks left aside, several of them reported as one a false rock: ``stockpile evaluate``'s
``of_interest``). The survey is
cached under ``--cache``.

With ``--bed`` the rocks cover the ground as a gravel bar's do (``stockpile_ros.tools.sim.bed``),
with ``--rounding`` their edges are worn round as a river's, ``--gradation`` sets their b: a
gravel bar such as #16's (about 1 cm spacing, b D50 about 0.2 m, a few hundred grains) is
``--bed --rounding 0.3 --gradation 0.1:0.4 --rocks 400 --spacing 0.01``. With ``--falloff 2``
the points thin out with range as a scanner's do (``--spacing`` is then the spacing nearest a
scanner); with ``--aspect 4`` they lie in rows four times farther apart across than along; with
``--no-overhead`` only the ring of tripods scans, at a glancing angle; ``--flat`` sets the share
of flat rocks; with ``--footprint 1`` a beam one spacing wide that straddles a rock's silhouette
returns a range between the rock and what lies behind it (mixed pixels); with ``--registration
0.005`` each position's scan is shifted by a registration error of 5 mm along each axis; with
``--noise-growth 2`` the range noise grows as the range squared from the nearest point's 2 mm.
``--formats ply`` runs one file of the three (a dense cloud takes minutes each).

With ``--meshes`` the same survey also goes in as two other tools' meshes, each through
``stockpile segment MESH --units m`` (the floor searched, ``settle_floor``) and scored through the
frame the run recorded: ``mesh:ours``, the PLY run's own Poisson mesh written back into the
cloud's frame (a mesh as clean as the cloud route makes; needs ``ply`` among ``--formats``), and
``mesh:user``, the survey moved to the origin and meshed as #16's user did (open3d's normals from
the 30 nearest within 5 spacings turned to +z, Poisson at depth 9, untrimmed). Their ``floor``
is the one kept.

Usage:
    .venv/bin/python bench/bench_cloud.py [--rocks N] [--spacing M] [--gradation LO:HI]
        [--bed] [--rounding R] [--falloff P] [--aspect A] [--flat F] [--no-overhead]
        [--footprint W] [--registration M] [--noise-growth P]
        [--formats ply xyz laz] [--meshes] [--cache DIR] [--set NAME=VALUE ...]
"""

from __future__ import annotations

import os

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ[_var] = '1'

import argparse  # noqa: E402
import contextlib  # noqa: E402
import pickle  # noqa: E402
import shutil  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import laspy  # noqa: E402
import numpy as np  # noqa: E402
import open3d as o3d  # noqa: E402

from stockpile_ros.artefacts import MeshInfo, load  # noqa: E402
from stockpile_ros.cli import main  # noqa: E402
from stockpile_ros.cloud import mesh_cloud, read_cloud  # noqa: E402
from stockpile_ros.meshio import read_labelled_mesh  # noqa: E402
from stockpile_ros.result import Report  # noqa: E402
from stockpile_ros.settings import build_settings, get_setting, smallest_rock_asked  # noqa: E402
from stockpile_ros.tools.sim.bed import BedConfig  # noqa: E402
from stockpile_ros.tools.sim.pile import PileConfig, parse_gradation  # noqa: E402
from stockpile_ros.tools.sim.survey import Survey, score_survey, simulate_survey  # noqa: E402


def survey(folder: Path, args: argparse.Namespace) -> Survey:
    """Return the cached survey, or simulate it (its truth in ``folder/truth``)."""
    path = folder / 'survey.pickle'
    if path.exists():
        # A cache pickled by an older layout of the package is simulated again.
        with contextlib.suppress(ModuleNotFoundError, AttributeError):
            loaded: Survey = pickle.loads(path.read_bytes())
            return loaded
    grading = parse_gradation(args.gradation)
    scene: PileConfig | BedConfig
    shares = {} if args.flat is None else {'flat_fraction': args.flat}
    if args.bed:
        scene = BedConfig(rocks=args.rocks, gradation=grading, rounding=args.rounding, **shares)
    else:
        scene = PileConfig(rocks=args.rocks, gradation=grading, rounding=args.rounding, **shares)
    made = simulate_survey(folder / 'truth', scene, seed=11, spacing=args.spacing, noise=0.002,
                           falloff=args.falloff, aspect=args.aspect,
                           overhead=args.overhead, footprint=args.footprint,
                           registration=args.registration,
                           noise_growth=args.noise_growth)  # fmt: skip
    path.write_bytes(pickle.dumps(made))
    return made


def write_files(s: Survey, folder: Path) -> list[tuple[Path, list[str]]]:
    """The survey as binary PLY, XYZ and LAZ, with the flags each is run with."""
    ply, xyz, laz = folder / 'survey.ply', folder / 'survey.xyz', folder / 'survey.laz'
    o3d.io.write_point_cloud(ply, o3d.geometry.PointCloud(o3d.utility.Vector3dVector(s.points)))
    np.savetxt(xyz, s.points, fmt='%.4f')
    header = laspy.LasHeader(point_format=3, version='1.4')
    header.offsets = s.points.min(axis=0)
    header.scales = np.full(3, 1e-4)
    las = laspy.LasData(header)
    las.x, las.y, las.z = s.points.T
    las.write(str(laz))
    return [(ply, ['--units', 'm']), (xyz, ['--units', 'm']), (laz, [])]


def run() -> None:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--rocks', type=int, default=220)
    # 7.5 mm: 135k points on this pile (1 cm: 77k).
    parser.add_argument('--spacing', type=float, default=0.0075)
    parser.add_argument('--gradation', default='0.1:0.35', help='b of the rocks [m]')
    parser.add_argument('--rounding', type=float, default=0.0, help='edges worn round [rad]')
    parser.add_argument('--bed', action='store_true', help='a bed covering the ground')
    parser.add_argument('--aspect', type=float, default=1.0,
                        help='scan lines: spacing across them over spacing along')  # fmt: skip
    parser.add_argument('--falloff', type=float, default=0.0,
                        help='density falling as range to this power (2: a scanner)')  # fmt: skip
    parser.add_argument('--flat', type=float,
                        help='share of flat rocks (c about 0.38 b), lying mostly flat')  # fmt: skip
    parser.add_argument('--no-overhead', dest='overhead', action='store_false',
                        help='scanned from the ring of tripods alone, none above')  # fmt: skip
    parser.add_argument('--footprint', type=float, default=0.0,
                        help="the scanner's beam width at the surface, in spacings: where it "
                        'straddles two surfaces, a mixed pixel between them')  # fmt: skip
    parser.add_argument('--registration', type=float, default=0.0,
                        help="each scanner position's points shifted together by a draw of "
                        'this standard deviation along each axis [m]')  # fmt: skip
    parser.add_argument('--noise-growth', type=float, default=0.0,
                        help='the 2 mm range noise grows as (range / nearest range) to this '
                        'power')  # fmt: skip
    parser.add_argument('--formats', nargs='+', default=['ply', 'xyz', 'laz'],
                        choices=['ply', 'xyz', 'laz'],
                        help='files to run (a dense cloud: one)')  # fmt: skip
    parser.add_argument('--meshes', action='store_true',
                        help="also as other tools' meshes: the PLY run's, a user's")  # fmt: skip
    parser.add_argument('--cache', type=Path, default=Path('/tmp/stockpile_bench_cloud'))
    parser.add_argument('--set', action='append', default=[], metavar='NAME=VALUE',
                        help="passed to stockpile segment's --set")  # fmt: skip
    args = parser.parse_args()
    overrides = [flag for item in args.set for flag in ('--set', item)]
    # The meshing timed on its own is the run's: the same cloud and Poisson settings.
    pairs = [item.split('=', 1) for item in args.set]
    settings = build_settings({name: get_setting(name).parse(text) for name, text in pairs})
    folder = args.cache / f'{args.rocks}_{args.spacing:g}'
    if args.bed or args.rounding or args.gradation != '0.1:0.35':
        kind = 'bed' if args.bed else 'pile'
        folder = folder.with_name(f'{folder.name}_{kind}_{args.gradation}_{args.rounding:g}')
    if args.falloff:
        folder = folder.with_name(f'{folder.name}_falloff{args.falloff:g}')
    if args.aspect != 1.0:
        folder = folder.with_name(f'{folder.name}_aspect{args.aspect:g}')
    if args.flat is not None:
        folder = folder.with_name(f'{folder.name}_flat{args.flat:g}')
    if not args.overhead:
        folder = folder.with_name(f'{folder.name}_ring')
    if args.footprint:
        folder = folder.with_name(f'{folder.name}_footprint{args.footprint:g}')
    if args.registration:
        folder = folder.with_name(f'{folder.name}_registration{args.registration:g}')
    if args.noise_growth:
        folder = folder.with_name(f'{folder.name}_noisegrowth{args.noise_growth:g}')
    folder.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    s = survey(folder, args)
    mixed = s.truth['scene']['survey'].get('mixed_pixels', 0)
    print(f'survey: {len(s.points)} points ({mixed} mixed pixels), {len(s.truth["rocks"])} rocks '
          f'({time.perf_counter() - start:.1f} s to simulate or load)')  # fmt: skip
    print(f'{"file":<12} {"MB":>6} {"to report s":>12} {"read+mesh s":>12} {"rocks":>6} '
          f'{"recall":>7} {"precision":>9} {"|b| err %":>9} {"D50 err %":>9} '
          f'{"floor m":>8} {"recall":>7} {"precision":>9}')  # fmt: skip
    for path, flags in write_files(s, folder):
        if path.suffix[1:] not in args.formats:
            continue
        out = folder / f'result_{path.suffix[1:]}'
        shutil.rmtree(out, ignore_errors=True)
        t0 = time.perf_counter()
        assert main(['segment', str(path), '--out', str(out), *flags, *overrides]) == 0
        total = time.perf_counter() - t0
        t1 = time.perf_counter()
        cloud = read_cloud(path)
        mesh_cloud(cloud, settings.cloud, settings.recon.poisson, 1.0, 'given',
                   min_rock_b=smallest_rock_asked(settings))  # fmt: skip
        meshing = time.perf_counter() - t1
        row(path.name, path, total, f'{meshing:12.1f}', score_survey(out, folder / 'truth', s))
    if args.meshes:
        for name, path, shift in other_meshes(s, folder, args.spacing):
            out = path.with_name(f'result_{path.stem}')
            shutil.rmtree(out, ignore_errors=True)
            t0 = time.perf_counter()
            assert main(['segment', str(path), '--units', 'm', '--out', str(out), *overrides]) == 0
            total = time.perf_counter() - t0
            record = load(Report, out / 'report.json').mesh.model_to_stockpile
            assert record is not None
            # From the cloud's frame: x_mesh = x_cloud - shift.
            rotation = np.asarray(record.rotation).reshape(3, 3)
            moved = [float(x) for x in record.translation - record.scale * rotation @ shift]
            info = MeshInfo(model_to_stockpile=replace(record, translation=moved))
            row(name, path, total, f'{"-":>12}', score_survey(out, folder / 'truth', s, info))


def row(name: str, path: Path, total: float, meshing: str, scores: dict[str, Any]) -> None:
    """Print one file's row of the table."""
    d = scores['detection']
    b = scores['sizes']['summary_visible']['b']['median_abs_pct']
    d50 = 100.0 * scores['gradation']['d50_error']
    size = path.stat().st_size / 1e6
    found = f'{d["recall_visible"]:7.2f} {d["precision_visible"]:9.2f} {b:9.1f} {d50:+9.1f}'
    it = d['of_interest']
    found += f' {it["min_b_m"]:8.3f} ' + ' '.join(
        '-'.rjust(w) if x is None else f'{x:{w}.2f}'
        for x, w in ((it['recall'], 7), (it['precision'], 9))
    )
    print(f'{name:<12} {size:6.1f} {total:12.1f} {meshing} {d["result_rocks"]:6d} {found}')


def other_meshes(s: Survey, folder: Path, spacing: float) -> list[tuple[str, Path, np.ndarray]]:
    """Write the survey as other tools' meshes: name, file and its shift from the cloud's frame."""
    made = []
    ours = folder / 'result_ply'
    if (ours / 'report.json').exists():
        record = load(Report, ours / 'report.json').mesh.model_to_stockpile
        assert record is not None
        mesh = read_labelled_mesh(ours / 'segments.ply')
        rotation = np.asarray(record.rotation).reshape(3, 3)
        back = ((mesh.vertices - record.translation) @ rotation) / record.scale
        path = folder / 'mesh_ours.ply'
        # Double precision: the cloud's frame is georeferenced, far from the origin.
        o3d.io.write_triangle_mesh(str(path), o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(back), o3d.utility.Vector3iVector(mesh.faces)))  # fmt: skip
        made.append(('mesh:ours', path, np.zeros(3)))
    shift = np.floor(s.points.min(axis=0))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(s.points - shift))
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=5 * spacing, max_nn=30))
    cloud.orient_normals_to_align_with_direction([0.0, 0.0, 1.0])
    user, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(cloud, depth=9)
    path = folder / 'mesh_user.ply'
    o3d.io.write_triangle_mesh(str(path), user)
    made.append(('mesh:user', path, shift))
    return made


if __name__ == '__main__':
    run()
