"""How far the next descent step may go: the vehicle's height above the chosen site, from every
measurement at hand, erring low."""

from __future__ import annotations

import math
from collections.abc import Sequence

from companion.guidance.frames import quat_to_matrix

MAX_RANGEFINDER_TILT_DEG = 10.0  # beyond this the beam lands too far from the site to say anything


def height_above_site(
    pos_d_m: float,
    *,
    surface_up_m: float,
    site_d_m: float,
    rangefinder_m: float,
    quat_wxyz: Sequence[float],
) -> float:
    """Height of the vehicle (down coordinate ``pos_d_m``) above the landing surface.

    Args:
        pos_d_m: the vehicle's NED down coordinate now.
        surface_up_m: the surface height at the site from the confirming LiDAR sweep (NED up, so it
            holds wherever the vehicle moved since the sweep); NaN when the sweep saw too little.
        site_d_m: the site's down coordinate from inverse perspective mapping when it was ranked;
            used when the LiDAR has no surface height.
        rangefinder_m: the downward rangefinder's slant range along body +z (NaN: none).
        quat_wxyz: the attitude the rangefinder reading was taken at.

    Returns:
        The height in metres, or NaN when nothing measured it.
        The rangefinder only ever lowers the answer (something under the vehicle nearer than the
        site), and only when the vehicle was within ``MAX_RANGEFINDER_TILT_DEG`` of level: a tilted
        beam can pass a roof's edge and read the street far below, and a descent by that reading
        would fly into the roof.
    """
    if math.isfinite(surface_up_m):
        height = -surface_up_m - pos_d_m
    elif math.isfinite(site_d_m):
        height = site_d_m - pos_d_m
    else:
        height = math.nan
    if math.isfinite(rangefinder_m) and rangefinder_m > 0:
        cos_tilt = float(quat_to_matrix(quat_wxyz)[2, 2])  # body +z against NED down
        if cos_tilt >= math.cos(math.radians(MAX_RANGEFINDER_TILT_DEG)):
            vertical = rangefinder_m * cos_tilt
            height = vertical if not math.isfinite(height) else min(height, vertical)
    return height
