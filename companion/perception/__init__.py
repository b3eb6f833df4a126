"""Perception: depth sources, Surface ID (flat-surface candidates), crops and the geometric site check."""

from companion.perception.depth import ArrayDepth, DepthError, DepthMap, DepthSource, LidarDepth
from companion.perception.site_check import SiteCheck, check_site
from companion.perception.surface_id import Candidate, SurfaceParams, propose, quadrant_fallback, surface_id

__all__ = [
    "ArrayDepth",
    "Candidate",
    "DepthError",
    "DepthMap",
    "DepthSource",
    "LidarDepth",
    "SiteCheck",
    "SurfaceParams",
    "check_site",
    "propose",
    "quadrant_fallback",
    "surface_id",
]
