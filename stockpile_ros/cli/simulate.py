"""``stockpile simulate``: render a camera-cart recording of a synthetic rock pile and its truth."""

from __future__ import annotations

import argparse
import math
from dataclasses import replace

from ..errors import StockpileError
from ..tools.sim.camera_path import PathConfig
from ..tools.sim.pile import PileConfig, parse_gradation
from ..tools.sim.record import SimulationConfig, simulate
from ..tools.sim.scene import SceneConfig

__all__ = ['DESCRIPTION', 'add_arguments', 'run']

DESCRIPTION = """\
Build a pile of angular rocks (sizes from --gradation, stacked by dropping each rock onto the
ground and the rocks already placed), lay an optional ChArUco board beside it, drive a camera cart
along a path and ray-trace every frame on the CPU. Writes the MCAP bag OUT (camera images or JPEG,
camera_info, /odom, /tf, /tf_static) and the truth folder OUT_truth/ (truth.json, scene.ply) as
docs/formats.md specifies. The same seed and options give the same scene and images.

Gradation: MIN:MAX (b in metres, mass spread evenly in log size) or D15=..,D50=..,D85=..
(percent passing by mass against b, extended to 0 and 100 %).
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the arguments of ``stockpile simulate``."""
    d_sim, d_path, d_pile = SimulationConfig(), PathConfig(), PileConfig()
    parser.add_argument('--out', required=True, metavar='BAG', help='bag folder to create')
    parser.add_argument('--seed', type=int, default=0, help='random seed (default %(default)s)')
    g = parser.add_argument_group('pile')
    g.add_argument(
        '--rocks', type=int, default=d_pile.rocks, help='number of rocks (default %(default)s)'
    )
    g.add_argument(
        '--gradation', default='0.12:0.3', help='size distribution of b (default %(default)s)'
    )
    g.add_argument('--flat', type=float, default=d_pile.flat_fraction, help='share of flat rocks')
    g.add_argument(
        '--elongated',
        type=float,
        default=d_pile.elongated_fraction,
        help='share of elongated rocks',
    )
    g.add_argument(
        '--rounding',
        type=float,
        default=d_pile.rounding,
        help="how far the rocks' edges are worn round [radians; 0: angular, 0.3: river cobbles]",
    )
    g.add_argument(
        '--spread',
        type=float,
        default=d_pile.spread,
        help='pile spread (smaller: higher pile; default %(default)s)',
    )
    g.add_argument(
        '--target',
        action=argparse.BooleanOptionalAction,
        default=True,
        help='ChArUco board on the ground',
    )
    p = parser.add_argument_group('camera path')
    p.add_argument('--path', choices=('arc', 'straight', 'orbit'), default=d_path.kind)
    p.add_argument(
        '--heights', type=int, choices=(1, 2), default=1, help='passes at one or two camera heights'
    )
    p.add_argument('--camera-height', type=float, default=1.0, help='first camera height [m]')
    p.add_argument('--camera-height2', type=float, default=1.5, help='second camera height [m]')
    p.add_argument(
        '--distance',
        type=float,
        help='distance from the pile centre [m] (default: from the pile size)',
    )
    p.add_argument('--arc', type=float, default=d_path.arc_degrees, help='arc angle [deg]')
    p.add_argument('--length', type=float, default=d_path.length, help='straight pass length [m]')
    c = parser.add_argument_group('camera')
    c.add_argument('--fps', type=float, default=d_sim.fps, help='frame rate (default %(default)s)')
    n = c.add_mutually_exclusive_group()
    n.add_argument('--frames', type=int, help='number of frames')
    n.add_argument('--duration', type=float, help='recording length [s] (default 10)')
    c.add_argument('--width', type=int, default=d_sim.width)
    c.add_argument('--height', type=int, default=d_sim.height, help='image height [px]')
    c.add_argument(
        '--hfov', type=float, default=d_sim.hfov_deg, help='horizontal field of view [deg]'
    )
    c.add_argument(
        '--compressed',
        action=argparse.BooleanOptionalAction,
        default=True,
        help='JPEG CompressedImage (--no-compressed or --raw: raw rgb8 Image)',
    )
    c.add_argument('--raw', dest='compressed', action='store_false', help='same as --no-compressed')
    c.add_argument('--jpeg-quality', type=int, default=d_sim.jpeg_quality)
    c.add_argument(
        '--noise', type=float, default=d_sim.sensor_noise, help='sensor noise [8-bit levels]'
    )
    c.add_argument('--blur', action='store_true', help='motion blur over the exposure time')
    c.add_argument('--exposure', type=float, default=0.02, help='exposure for --blur [s]')
    c.add_argument('--no-shadows', dest='shadows', action='store_false', help='no cast shadows')
    o = parser.add_argument_group('odometry')
    o.add_argument('--odom-rate', type=float, default=d_sim.odom_rate, help='odometry rate [Hz]')
    o.add_argument(
        '--odom-noise',
        type=float,
        default=0.0,
        metavar='SIGMA',
        help='odometry drift [m per sqrt(m) travelled] (default 0)',
    )
    parser.add_argument('--threads', type=int, default=0, help='ray-casting threads (0: all cores)')


def run(args: argparse.Namespace) -> int:
    """Run ``stockpile simulate``."""
    if args.frames is not None:
        frames = args.frames
    else:
        duration = 10.0 if args.duration is None else args.duration
        frames = math.floor(duration * args.fps + 1e-9) + 1
    if args.width < 8 or args.height < 8:
        raise StockpileError('images must be at least 8 x 8 pixels')
    pile = replace(
        PileConfig(),
        rocks=args.rocks,
        gradation=parse_gradation(args.gradation),
        flat_fraction=args.flat,
        elongated_fraction=args.elongated,
        spread=args.spread,
        rounding=args.rounding,
    )
    first, second = args.camera_height, args.camera_height2
    heights = (first,) if args.heights == 1 else (first, second)
    path = replace(
        PathConfig(),
        kind=args.path,
        heights=heights,
        distance=args.distance,
        arc_degrees=args.arc,
        length=args.length,
    )
    cfg = SimulationConfig(
        seed=args.seed,
        scene=SceneConfig(pile=pile, target=args.target),
        path=path,
        width=args.width,
        height=args.height,
        hfov_deg=args.hfov,
        fps=args.fps,
        frames=frames,
        compressed=args.compressed,
        jpeg_quality=args.jpeg_quality,
        odom_rate=args.odom_rate,
        odom_noise=args.odom_noise,
        exposure=args.exposure if args.blur else 0.0,
        sensor_noise=args.noise,
        shadows=args.shadows,
        threads=args.threads,
    )
    summary = simulate(cfg, args.out)
    d50 = summary.truth_data['gradation']['d50']
    d50_text = 'undefined' if d50 is None else f'{d50:.3f} m'
    print(
        f'wrote {summary.bag} ({summary.frames} frames, {summary.rocks} rocks) '
        f'and {summary.truth}; true D50 {d50_text}'
    )
    return 0
