"""A stockpile simulator: rendered camera-cart bags of rock piles with exact ground truth.

:func:`~stockpile_ros.tools.sim.record.simulate` is the entry point (``stockpile simulate`` calls
it); the modules are usable alone: :mod:`.rocks` (rock meshes), :mod:`.pile` (gradation and
stacking), :mod:`.texture`, :mod:`.camera_path`, :mod:`.render` (CPU ray casting), :mod:`.truth`,
:mod:`.record`, and :mod:`.bed` (beds of hundreds of rocks, meshed without rendering: the
segmentation's field-like yardstick).
"""

from __future__ import annotations

from .camera_path import CartPath, PathConfig
from .pile import Gradation, PileConfig, parse_gradation
from .record import SimulationConfig, SimulationSummary, simulate, truth_folder
from .render import Renderer
from .scene import Scene, SceneConfig, build_scene

__all__ = [
    'CartPath',
    'Gradation',
    'PathConfig',
    'PileConfig',
    'Renderer',
    'Scene',
    'SceneConfig',
    'SimulationConfig',
    'SimulationSummary',
    'build_scene',
    'parse_gradation',
    'simulate',
    'truth_folder',
]
