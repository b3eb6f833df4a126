"""The configured depth source: the LiDAR, the monocular network, or the LiDAR with the network behind
it. Above both :mod:`companion.perception.depth` and :mod:`companion.perception.mono_depth`."""

from __future__ import annotations

from pathlib import Path

from companion.config_schema import DEFAULTS
from companion.perception.depth import DepthError, DepthSource, FirstAvailable, LidarDepth

__all__ = ["make_source"]


def make_source(
    kind: str,
    *,
    cell_px: int = DEFAULTS.perception.cell_px,
    model: str | Path | None = None,
    lidar_range_m: float = DEFAULTS.perception.lidar_range_m,
) -> DepthSource:
    """A configured depth source: ``lidar``, ``depth-anything`` or ``auto`` (LiDAR, else the image).

    Loading the monocular network happens here, so a missing extra or missing weights fail at start-up.
    """
    if kind == "lidar":
        return LidarDepth(cell_px=cell_px, range_m=lidar_range_m)
    if kind in ("depth-anything", "auto"):
        from companion.perception.mono_depth import DEFAULT_MODEL, DepthAnythingV2  # torch: lazily

        mono = DepthAnythingV2(model or DEFAULT_MODEL, cell_px=cell_px)
        return (
            mono
            if kind == "depth-anything"
            else FirstAvailable((LidarDepth(cell_px=cell_px, range_m=lidar_range_m), mono))
        )
    raise DepthError(f"unknown depth source {kind!r}; use lidar, depth-anything or auto")
