"""Camera models and decoded camera frames, the currency between bag input and the pipeline."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ['CameraModel', 'Frame']


@dataclass(frozen=True)
class CameraModel:
    """A pinhole camera with optional distortion, as in ``sensor_msgs/CameraInfo``.

    Attributes:
        width: Image width [px].
        height: Image height [px].
        k: 3x3 intrinsic matrix.
        d: Distortion coefficients (may be empty).
        distortion_model: ``"plumb_bob"``, ``"rational_polynomial"``, ``"equidistant"`` or ``""``.
        frame_id: Optical frame of the camera (REP 103: z forward, x right, y down).

    """

    width: int
    height: int
    k: npt.NDArray[np.float64]
    d: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    distortion_model: str = 'plumb_bob'
    frame_id: str = 'camera_optical_frame'

    @property
    def fx(self) -> float:
        """Focal length along x [px]."""
        return float(self.k[0, 0])

    @property
    def fy(self) -> float:
        """Focal length along y [px]."""
        return float(self.k[1, 1])

    @property
    def cx(self) -> float:
        """Principal point x [px]."""
        return float(self.k[0, 2])

    @property
    def cy(self) -> float:
        """Principal point y [px]."""
        return float(self.k[1, 2])

    def fits(self, image: npt.NDArray[np.generic]) -> bool:
        """Whether this model describes ``image``: its size must match (else self-calibrate)."""
        return (self.height, self.width) == image.shape[:2]

    def to_dict(self) -> dict[str, Any]:
        """JSON form (as in ``keyframes.jsonl``)."""
        return {
            'width': self.width,
            'height': self.height,
            'k': [float(v) for v in np.asarray(self.k).ravel()],
            'd': [float(v) for v in np.asarray(self.d).ravel()],
            'distortion_model': self.distortion_model,
            'frame_id': self.frame_id,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> CameraModel:
        """Inverse of :meth:`to_dict`."""
        return cls(
            width=int(data['width']),
            height=int(data['height']),
            k=np.asarray(data['k'], dtype=np.float64).reshape(3, 3),
            d=np.asarray(data.get('d', []), dtype=np.float64),
            distortion_model=str(data.get('distortion_model', 'plumb_bob')),
            frame_id=str(data.get('frame_id', 'camera_optical_frame')),
        )

    @classmethod
    def from_fov(cls, width: int, height: int, hfov_deg: float, **kwargs: Any) -> CameraModel:
        """Build a distortion-free camera from its horizontal field of view."""
        f = 0.5 * width / np.tan(np.radians(hfov_deg) / 2)
        k = np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])
        return cls(width=width, height=height, k=k, **kwargs)


@dataclass
class Frame:
    """One decoded camera image.

    Attributes:
        stamp_ns: Header stamp [ns].
        image: HxWx3 uint8 RGB, or HxW uint8/uint16 for mono sources.
        frame_id: Header frame id.
        camera: The matching camera model, None when the bag has no CameraInfo for it.
        topic: Topic the frame came from.
        index: Index of the message within its topic.

    """

    stamp_ns: int
    image: npt.NDArray[np.generic]
    frame_id: str
    camera: CameraModel | None = None
    topic: str = ''
    index: int = 0
