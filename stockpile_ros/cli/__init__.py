"""The ``stockpile`` command: one module per subcommand in this package.

Each subcommand module defines ``DESCRIPTION`` (its ``--help`` text), ``add_arguments(parser)`` and
``run(args) -> int``, and stays thin over the core. Only the module of the subcommand being run is
imported, so ``stockpile info`` never pays for open3d or pycolmap.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from .. import __version__
from ..errors import StockpileError

__all__ = ['COMMANDS', 'build_parser', 'main']

# Subcommand -> one-line help, in the order --help lists them.
COMMANDS = {
    'info': 'summarise a ROS 2 bag: topics, images, camera_info, odometry, problems',
    'replay': 'measure the rocks of a bag (through the node set), a folder of photos or a video',
    'reconstruct': 'reconstruct a metric, gravity-aligned Poisson mesh from a bag, photos or video',
    'segment': 'segment a stockpile mesh into rocks and report sizes, shapes and gradation',
    'simulate': 'render a ROS 2 bag of a synthetic rock pile with its ground truth',
    'evaluate': 'score a result folder against a simulator truth folder',
    'target': 'write a PDF of a scale target at true size, with its spec and a check line',
}


def _chosen(argv: Sequence[str]) -> str | None:
    """Return the subcommand named on the command line (the first word that is one)."""
    return next((word for word in argv if word in COMMANDS), None)


def build_parser(argv: Sequence[str]) -> argparse.ArgumentParser:
    """Build the parser; only the subcommand named in ``argv`` gets its module loaded."""
    parser = argparse.ArgumentParser(
        prog='stockpile',
        description='Measure the rocks of a stockpile from a camera recording (ROS 2 bags).',
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    chosen = _chosen(argv)
    for name, help_text in COMMANDS.items():
        if name != chosen:
            sub.add_parser(name, help=help_text)
            continue
        module = importlib.import_module(f'.{name}', __name__)
        cmd = sub.add_parser(
            name,
            help=help_text,
            description=module.DESCRIPTION,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        module.add_arguments(cmd)
        cmd.set_defaults(run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``stockpile`` command; returns the exit status."""
    words = list(sys.argv[1:] if argv is None else argv)
    args = build_parser(words).parse_args(words)
    try:
        status: int = args.run(args)
    except StockpileError as exc:
        print(f'stockpile {args.command}: error: {exc}', file=sys.stderr)
        return 2
    except OSError as exc:
        # A file-system fault (full disk, read-only, permissions): the path and the fault.
        where = f'{exc.filename}: ' if exc.filename else ''
        print(f'stockpile {args.command}: error: {where}{exc.strerror or exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f'stockpile {args.command}: interrupted', file=sys.stderr)
        return 130
    return status


if __name__ == '__main__':
    sys.exit(main())
