"""Guidance: frames and the camera model, inverse perspective mapping (pixel -> NED)."""

from companion.guidance.frames import (
    CAMERA_TO_BODY,
    GeometryInputError,
    PinholeCamera,
    frd_to_ned,
    quat_to_matrix,
)
from companion.guidance.ipm import (
    DEFAULT_MAX_PX,
    IpmError,
    IpmHit,
    LidarPixelIndex,
    LidarUnavailable,
    NoReturnNearPixel,
    RayDoesNotDescend,
    ground_down_from_range,
    pixel_to_ned,
    pixel_to_ned_flat,
    pixel_to_ned_surface,
)

__all__ = [
    "CAMERA_TO_BODY",
    "DEFAULT_MAX_PX",
    "GeometryInputError",
    "IpmError",
    "IpmHit",
    "LidarPixelIndex",
    "LidarUnavailable",
    "NoReturnNearPixel",
    "PinholeCamera",
    "RayDoesNotDescend",
    "frd_to_ned",
    "ground_down_from_range",
    "pixel_to_ned",
    "pixel_to_ned_flat",
    "pixel_to_ned_surface",
    "quat_to_matrix",
]
