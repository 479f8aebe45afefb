"""Everything the reconstruction stages can be tuned with, in one record."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

from ..ranges import Range
from ..ros.images import DEFAULT_MAX_PIXELS
from .dense import DenseOptions
from .gates import GateOptions
from .keyframes import SelectorOptions
from .scale import Target
from .sfm import SfmOptions
from .surface import PoissonOptions

__all__ = ['ReconOptions']


@dataclass(frozen=True)
class ReconOptions:
    """Everything the stages can be tuned with.

    Attributes:
        topic: Image topic of a bag (None: the one with most messages).
        selector: Keyframe selection.
        sfm: Structure-from-Motion.
        dense: Dense stereo.
        gate: The registration gate after Structure-from-Motion.
        poisson: Surface.
        target: The scale targets in view, '' for none (sizes in metres):
            aruco:DICT:ID:SIZE_M (one marker, the edge of its black square),
            aruco:DICT:*:SIZE_M (every marker of the dictionary), apriltag:36h11:ID:SIZE_M,
            bar:DICT:ID1:ID2:DIST_M (two markers whose centres are DIST_M apart) or
            charuco:SXxSY:SQUARE_M:MARKER_M[:DICT]; several joined by commas.
        use_odometry: Scale from the bag's odometry when it has some.
        odometry_scale_uncertainty: Relative standard deviation of the odometry's own scale
            (wheel radius, tyre pressure, slip; 1-2 % for wheel odometry), added in quadrature
            to the fit's: the fit against the SfM path cannot see it.
        target_size_uncertainty: Relative standard deviation of a printed marker's or bar's
            true size, added in quadrature to the spread of its detections (0.3 %: a 150 mm
            marker checked with a ruler to 0.5 mm).
        odometry_tolerance: Odometry is not used for the scale when the keyframe path, scaled
            onto it, differs from it by more than this share of its extent (rms). A keyframe
            further than this share from where odometry puts it, after the fit to the others, is
            left out of the dense and mesh stages (see ``on_path``).
        crop_radius: Points farther (horizontally) from the pile centre than this multiple of
            the pile's radius (95 % of what rises above a tenth of its height) are left out of the
            surface,
            and never farther than the farthest camera (0 keeps all): far ground seen at grazing
            angles only costs Poisson resolution.
        max_image_pixels: Largest image accepted, width x height, checked from the header
            before it is decoded (a bag's image or a photo that claims more is refused with the
            reason): bounds what one image can cost in memory, 3 bytes a pixel and a few copies.

    """

    topic: str | None = None
    selector: SelectorOptions = field(default_factory=SelectorOptions)
    sfm: SfmOptions = field(default_factory=SfmOptions)
    dense: DenseOptions = field(default_factory=DenseOptions)
    gate: GateOptions = field(default_factory=GateOptions)
    poisson: PoissonOptions = field(default_factory=PoissonOptions)
    target: tuple[Target, ...] = ()
    use_odometry: bool = True
    odometry_scale_uncertainty: Annotated[float, Range(0.0, 0.5)] = 0.02
    target_size_uncertainty: Annotated[float, Range(0.0, 0.2)] = 0.003
    crop_radius: Annotated[float, Range(0.0, 100.0)] = 1.5
    odometry_tolerance: Annotated[float, Range(0.0, 10.0)] = 0.05
    max_image_pixels: Annotated[int, Range(10_000, 1_000_000_000)] = DEFAULT_MAX_PIXELS
