"""A yardstick that looks like the field: beds of hundreds of rocks per material, meshed at 4-30
edges across the smallest rock's b, segmented and measured with the default mode.

Per material (``stockpile_ros.tools.sim.bed.MATERIALS``: aggregate 20-80 mm, cobble 0.1-0.3 m,
riprap 0.3-1.5 m) one bed of ``--rocks`` rocks covering the ground (``build_bed``), surveyed from
above and meshed by Poisson at each resolution (finest cell = the smallest b over ``--edges``;
the median edge comes out within a few percent of the cell), the points displaced along their
normals by a smooth random relief of ``--relief`` cells over ``--relief-length`` cells and by
white noise of ``--noise`` cells (``bed_surface``). The default relief, 0.3 cells over 3, is
where the bed's open ground reads as the demo pile's reconstructed ground does to the valley test
(``valley_depths``; share of flat faces deeper than ``valley_depth_ratio`` radii at 1, 1.5, 3
and 4 edge lengths: demo 0.15, 0.17, 0.13, 0.13; bed without relief 0.03, 0.02, 0.04, 0.05; 0.15
cells 0.06 at each; 0.3 cells 0.12, 0.13, 0.14, 0.12; measured on the cobble bed at 20 edges with
0.2 cells of noise). The default noise, 0.6 cells, is where the open ground is as rough face to
face as a reconstructed pile's: of the directed edges between flat ground faces, the share that
fails Eq. 2 at the default threshold is 0.25 (the README's five reconstructed piles: 0.21, 0.26,
0.27, 0.28, 0.29; 0.2 cells: 0.13, 0.4 cells: 0.22; the relief moves it little: 0.3 cells over
1.5 gives 0.18 and 0.5 over 3 0.16). Poisson's normals are estimated, as a survey or dense
matching has them: a plane fit to the ``--normal-neighbours`` nearest noisy points (the cloud
route's ``cloud.neighbours`` by default), turned towards the ray that found each point (0: the
true normals, which round no edge).
With ``--rounding`` every rock's edges are worn round as a river's (``random_rock``: radians of
the smoothing of its radius; 0.3 for river cobbles; the same sizes, shapes and places).
With ``--wave`` the bed lies on uneven ground (``drape``: a wave of that amplitude and
``--wave-length``, both in units of the largest b; 0: flat). Then the product's
``segment_and_measure`` with the smallest and largest rocks set to the material's smallest and
largest b (as a class check would set them; open ground off the plane found as bare patches wider
than the largest rock, ``stockpile_ros.segment.ground``; regions thinner than a sheet left out
as ground), and the score
against the true label of every face (``score_labels``: visible = at least 30 % of the rock's
surface seen, one-to-one matches at surface IoU >= 0.5, reported rocks about barely visible ones
counted neither way; the D50 error against every true rock, as ``stockpile evaluate`` scores it,
and against the visible ones; ``D50 90%`` is the interval a report gives the D50 (at
``ReportOptions``' confidence, 90 %), from ``bootstrap_intervals`` over the reported rocks with
no doubt on the scale, against the same true D50: whether the uncertainty the product states
holds the truth). One row per material and resolution;
``edges/b`` is the smallest b over the mesh's median edge; ``seconds`` is the CPU time of
``segment_and_measure`` on one thread (which cores shared with other work do not inflate), and
its growth with the face count (a least-squares power law over the resolutions) ends each
material; ``floor`` says ``cuts`` where a report would warn that the mesh's floor cuts the pile's
sizes (``truncation_warnings``: only with no smallest rock given, ``--set min_rock_b=0``).
With ``--steps`` each row is followed by what each step of ``segment_mesh`` left of
the visible rocks (``label_outcomes``: each rock through the region holding most of it, matched
at IoU 0.5, in a region with other surface, in pieces, or short of that), to tell which step
gains and which loses rocks (from the row's own run, whose seconds then include copying the
labels). With ``--bands`` each row is followed by, in bands of the true rocks' visible fraction,
how many of them were found (matched one to one) and their mass against the measured mass of the
reported rocks lying mostly on rocks of that band (the recall counts every rock at least 30 %
visible, and the D50 is by mass against every rock, buried ones included: this tells which rocks
carry their errors). With ``--true-labels`` each row is followed by the same measurement on the
true labels (every rock's seen surface one region, as a segmentation that never erred would
report it, slivers of buried rocks included and sheets left out as ``segment_and_measure`` leaves
them), scored the same way: what of the row's median b error and D50 error the measurement of the
seen surfaces carries whatever the segmentation does. With ``--floor F`` the smallest rock of
interest is F times the material's smallest b, so that the bed's smaller rocks are fines under
it, as a gravel bar's are under what its survey resolves: they are scored as the barely visible
ones are (neither missed nor, found alone, counted either way; ``score_labels``' ``min_b``), the
recall and ``D50 vis`` are over the rocks at or above it, and a line under the row counts the
reported rocks made of several fines (false rocks). With ``--search-floor`` the floor is searched
as for another tool's mesh (``settle_floor``: where it is above the smallest rock asked for, or
none is asked, ``--floor 0``), ``floor`` giving the one kept in median edge lengths (``!`` where
the sizes still pile up against it; ``seconds`` then counts every floor tried); ``--floor 0``
alone keeps the floor at ``segment.min_rock_edges`` with no smallest rock given, as another
tool's mesh had it before the search. The beds and their meshed surfaces are kept under
``--cache`` (a 30-edge surface is about 100 MB), so a sweep of segmentation settings meshes each
surface once.

Usage:
    .venv/bin/python bench/bench_yardstick.py [--rocks 300] [--edges 4 8 12 20 30]
        [--materials aggregate cobble riprap] [--rounding 0] [--noise 0.6] [--relief 0.3]
        [--relief-length 3] [--normal-neighbours 20] [--wave 0] [--wave-length 10]
        [--steps] [--bands] [--true-labels] [--floor 1] [--set FIELD=VALUE ...]
"""

from __future__ import annotations

import os

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ[_var] = '1'

import argparse  # noqa: E402
import ast  # noqa: E402
import contextlib  # noqa: E402
import dataclasses  # noqa: E402
import hashlib  # noqa: E402
import itertools  # noqa: E402
import pickle  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Collection  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from stockpile_ros.cloud.mesh import CloudOptions  # noqa: E402
from stockpile_ros.segment.measure import (  # noqa: E402
    MeasureParams,
    RockMeasure,
    measure_rocks,
    split_sheets,
)
from stockpile_ros.segment.params import SegmentParams  # noqa: E402
from stockpile_ros.segment.pipeline import (  # noqa: E402
    segment_and_measure,
    settle_floor,
    truncation_warnings,
)
from stockpile_ros.segment.qa import ReportOptions, bootstrap_intervals  # noqa: E402
from stockpile_ros.segment.segmentation import Segmentation  # noqa: E402
from stockpile_ros.tools.evaluation.labels import (  # noqa: E402
    OUTCOMES,
    LabelScore,
    SizedRock,
    label_outcomes,
    score_labels,
)
from stockpile_ros.tools.evaluation.match import MatchOptions  # noqa: E402
from stockpile_ros.tools.sim import bed as sim_bed  # noqa: E402
from stockpile_ros.tools.sim import pile as sim_pile  # noqa: E402
from stockpile_ros.tools.sim import rocks as sim_rocks  # noqa: E402
from stockpile_ros.tools.sim.bed import (  # noqa: E402
    MATERIALS,
    BedConfig,
    BedSurface,
    bed_surface,
    build_bed,
    drape,
)
from stockpile_ros.tools.sim.pile import Gradation  # noqa: E402


def cached(path: Path, make: Callable[[], Any]) -> Any:
    """``make()``, kept pickled at ``path`` and read from there when it is there."""
    if path.exists():
        # A cache pickled by an older layout of the package is built again.
        with contextlib.suppress(ModuleNotFoundError, AttributeError):
            return pickle.loads(path.read_bytes())
    made = make()
    path.write_bytes(pickle.dumps(made))
    return made


#: The simulator's source: a cache made by other code is made again.
SOURCE = b''.join(Path(m.__file__).read_bytes() for m in (sim_bed, sim_pile, sim_rocks))


def bed(material: str, rocks: int, seed: int, rounding: float, cache: Path):
    lo, hi = MATERIALS[material]
    cfg = BedConfig(rocks=rocks, gradation=Gradation((lo, hi), (0.0, 100.0)), rounding=rounding)
    key = hashlib.sha1(repr(cfg).encode() + SOURCE).hexdigest()[:16]
    return cached(
        cache / f'{material}-{rocks}-{seed}-{key}.pickle',
        lambda: build_bed(np.random.default_rng(seed), cfg),
    )


def surveyed(placed, material: str, across: float, args: argparse.Namespace) -> BedSurface:
    """The bed surveyed and meshed at ``across`` edges, from the cache when made alike before.

    A 30-edge surface takes minutes to mesh and segments in seconds, so sweeps of segmentation
    parameters reuse it; the key holds every survey setting and the simulator's own source, so
    a changed simulator meshes again.
    """
    lo, hi = MATERIALS[material]
    drawn = ('rocks', 'seed', 'rounding')
    survey = ('noise', 'relief', 'relief_length', 'normal_neighbours', 'wave')
    settings = (material, across, args.wave_length, *(getattr(args, k) for k in drawn + survey))
    key = hashlib.sha1(repr(settings).encode() + SOURCE).hexdigest()[:16]

    def make() -> BedSurface:
        surface = bed_surface(
            placed,
            lo / across,
            np.random.default_rng(args.seed),
            args.noise,
            relief_cells=args.relief,
            relief_length_cells=args.relief_length,
            normal_neighbours=args.normal_neighbours,
        )
        return drape(surface, args.wave * hi, args.wave_length * hi) if args.wave else surface

    return cached(args.cache / f'surface-{material}-{across:g}-{key}.pickle', make)


#: Bands of the visible fraction ``--bands`` counts the rocks and sums the masses in.
VISIBLE_BANDS = (0.0, 0.1, 0.3, 0.4, 0.5, 1.0)


def by_visibility(
    surface: BedSurface,
    labels: np.ndarray,
    areas: np.ndarray,
    rocks: list[RockMeasure],
    found: Collection[int],
) -> str:
    """Return per band of visible fraction the true rocks, those ``found`` and their masses [kg].

    The measured mass of each reported rock counts in the band of the true rock under most of
    its area (``on ground`` where that is the ground).
    """
    width = int(surface.labels.max()) + 1
    pair = labels.astype(np.int64) * width + surface.labels
    shared = np.bincount(pair, weights=areas, minlength=(int(labels.max()) + 1) * width)
    shared = shared.reshape(-1, width)
    truth = [surface.rocks.get(k) for k in range(width)]
    seen = np.array([-1.0 if r is None else r['visible_fraction'] for r in truth])
    true_mass = np.array([0.0 if r is None else r['mass'] for r in truth])
    band = np.searchsorted(VISIBLE_BANDS[1:-1], seen, side='right')
    hit = np.isin(np.arange(width), list(found))
    measured = np.zeros(len(VISIBLE_BANDS))
    for rock in rocks:
        under = int(np.argmax(shared[rock.id]))
        # The last slot holds what lies on the ground.
        measured[band[under] if seen[under] >= 0 else -1] += rock.mass
    parts = []
    for i, (lo, hi) in enumerate(itertools.pairwise(VISIBLE_BANDS)):
        inside = (band == i) & (seen >= 0)
        parts.append(
            f'{lo:4.0%}-{hi:4.0%} visible: {hit[inside].sum():3d} of {inside.sum():3d} found, mass '
            f'{true_mass[inside].sum():8.3g} kg true, {measured[i]:8.3g} kg measured'
        )
    return '\n'.join([*parts, f'on ground: {measured[-1]:.3g} kg measured'])


def on_true_labels(
    surface: BedSurface, seg: Segmentation, truth: dict[int, SizedRock]
) -> LabelScore:
    """Score the product's measurement of the true labels of ``surface`` (``seg``'s mesh)."""
    true = dataclasses.replace(seg, labels=surface.labels.astype(np.int32))
    params = MeasureParams()
    rocks, _ = split_sheets(measure_rocks(surface.vertices, true, params), params)
    measured = {r.id: SizedRock(r.b, r.mass) for r in rocks}
    return score_labels(surface.labels, true.labels, seg.geometry.areas, truth, measured)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rocks', type=int, default=300)
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--edges', type=float, nargs='+', default=[4.0, 8.0, 12.0, 20.0, 30.0])
    parser.add_argument('--materials', nargs='+', default=list(MATERIALS), choices=list(MATERIALS))
    parser.add_argument(
        '--rounding', type=float, default=0.0, help="rocks' edges worn round [radians; 0.3: river]"
    )
    parser.add_argument('--noise', type=float, default=0.6, help='point noise [Poisson cells]')
    parser.add_argument('--relief', type=float, default=0.3, help='smooth relief [cells]')
    parser.add_argument('--relief-length', type=float, default=3.0, help='its length [cells]')
    parser.add_argument(
        '--normal-neighbours',
        type=int,
        default=CloudOptions().neighbours,
        help='normals estimated from this many points [0: true normals]',
    )
    parser.add_argument('--wave', type=float, default=0.0, help='ground wave [largest b]')
    parser.add_argument('--wave-length', type=float, default=10.0, help='its length [largest b]')
    parser.add_argument(
        '--steps', action='store_true', help='after each row, what each step left of its rocks'
    )
    parser.add_argument(
        '--true-labels',
        action='store_true',
        help='after each row, the same measurement and score on the true labels',
    )
    parser.add_argument(
        '--bands',
        action='store_true',
        help='after each row, rocks found and mass by band of visible fraction',
    )
    parser.add_argument(
        '--floor',
        type=float,
        default=1.0,
        help="smallest rock of interest [the material's smallest b]: over 1, the bed's smaller "
        'rocks are fines under it, scored as barely visible ones',
    )
    parser.add_argument(
        '--search-floor',
        action='store_true',
        help="the floor searched as for another tool's mesh (no smallest rock given: --floor 0)",
    )
    parser.add_argument('--set', nargs='*', default=[], metavar='FIELD=VALUE')
    parser.add_argument('--cache', type=Path, default=Path('/tmp/stockpile_bench_yardstick'))
    args = parser.parse_args()
    if args.search_floor and args.steps:
        parser.error('--steps follows one segmentation; --search-floor runs several')
    args.cache.mkdir(parents=True, exist_ok=True)
    overrides = {k: ast.literal_eval(v) for k, v in (s.split('=', 1) for s in args.set)}
    normals = f'from {args.normal_neighbours} points' if args.normal_neighbours else 'true'
    print(f'{args.rocks} rocks per bed, seed {args.seed}, rounding {args.rounding} rad, '
          f'noise {args.noise} cells, relief '
          f'{args.relief} cells over {args.relief_length}; normals {normals}; ground wave '
          f'{args.wave} largest b over {args.wave_length}; '
          f'overrides: {overrides or "none"}')  # fmt: skip
    print('material  b range m   edges/b  faces    visible reported found recall precision '
          'merges splits  |b err| b bias  D50 err  D50 vis  seconds  floor  '
          f'D50 {ReportOptions().confidence:.0%}')  # fmt: skip
    for material in args.materials:
        placed = bed(material, args.rocks, args.seed, args.rounding, args.cache)
        lo, hi = MATERIALS[material]
        cost = []
        for across in args.edges:
            surface = surveyed(placed, material, across, args)
            params = SegmentParams.preset(
                'default', **{'min_rock_b': args.floor * lo, 'max_rock_b': hi, **overrides}
            )
            steps: list[tuple[str, np.ndarray]] = []
            t0 = time.process_time()
            if args.search_floor:
                measured, _ = settle_floor(surface.vertices, surface.faces, params, MeasureParams())
            else:
                measured = segment_and_measure(
                    surface.vertices,
                    surface.faces,
                    params,
                    MeasureParams(),
                    # Copies: a step's labels are read while it runs, not kept.
                    on_step=(lambda name, labels, kept=steps: kept.append((name, labels.copy())))
                    if args.steps
                    else None,
                )
            seg, rocks = measured.segmentation, measured.rocks
            seconds = time.process_time() - t0
            truth = {
                k: SizedRock(r['b'], r['mass'], r['visible_fraction'])
                for k, r in surface.rocks.items()
            }
            s = score_labels(
                surface.labels,
                seg.labels,
                seg.geometry.areas,
                truth,
                {r.id: SizedRock(r.b, r.mass) for r in rocks},
                min_b=params.min_rock_b,
            )
            edges = lo / seg.scale.edge
            # Whether a report would say the mesh's floor cuts the sizes (only with no smallest
            # rock given: --set min_rock_b=0).
            cut = truncation_warnings(seg.scale, [r.b for r in rocks], 'm')
            floor = 'cuts' if cut else '-'
            if args.search_floor:
                floor = f'{seg.params.min_rock_edges:.3g}{"!" if cut else ""}'
            lo_d50, hi_d50 = bootstrap_intervals(
                [r.b for r in rocks], [r.mass for r in rocks], 0.0
            ).mass['d50']
            interval = '  '.join(
                '-' if x is None else f'{100 * (x / s.d50_true - 1):+.0f}%'
                for x in (lo_d50, hi_d50)
            )
            print(f'{material:9s} {lo:4.2f}-{hi:4.2f}  {edges:7.1f} {len(surface.faces):8d} '
                  f'{s.visible:7d} {s.reported:8d} {s.found:5d} {s.recall:6.3f} '
                  f'{s.precision:9.3f} {s.merges:6d} {s.splits:6d}  {100 * s.b_error:6.1f}% '
                  f'{100 * s.b_bias:+5.1f}% {100 * s.d50_error:+6.1f}%  '
                  f'{100 * s.d50_error_visible:+6.1f}%  {seconds:7.1f}  {floor:5s}  {interval}',
                  flush=True)  # fmt: skip
            cost.append((len(surface.faces), seconds))
            seen = MatchOptions().visible_threshold
            small = [r for r in truth.values() if r.b < params.min_rock_b]
            if small:
                print(f'    fines under the smallest rock of interest ({params.min_rock_b:.3g} m): '
                      f'{len(small)} rocks, {sum(r.visible_fraction >= seen for r in small)} '
                      f'of them visible; {s.clusters} reported rocks made of them')  # fmt: skip
            visible = [
                k
                for k, r in truth.items()
                if r.visible_fraction >= seen and r.b >= params.min_rock_b
            ]
            if args.bands:
                found = [k for _, k in s.pairs]
                bands = by_visibility(surface, seg.labels, seg.geometry.areas, rocks, found)
                print('\n'.join('    ' + line for line in bands.splitlines()))
            if args.true_labels:
                t = on_true_labels(surface, seg, truth)
                print(f'    on the true labels: {t.reported} rocks, median b error '
                      f'{100 * t.b_error:.1f}%, b bias {100 * t.b_bias:+.1f}%, D50 error '
                      f'{100 * t.d50_error:+.1f}% (against the visible rocks '
                      f'{100 * t.d50_error_visible:+.1f}%)')  # fmt: skip
            for name, labels in steps:
                outcome = label_outcomes(surface.labels, labels, seg.geometry.areas, visible)
                print(f'    after {name:16s}' + ', '.join(f'{k} {outcome[k]}' for k in OUTCOMES))
        if len(cost) >= 2:
            faces, secs = np.log(np.array(cost)).T
            growth = np.polyfit(faces, secs, 1)[0]
            print(f'{material}: segmentation and measurement cost grows as faces^{growth:.2f}')


if __name__ == '__main__':
    main()
