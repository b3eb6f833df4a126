"""The onboard tier's parameters: how Surface ID's geometry scores a candidate, and when a close-up is
accepted. Below both judges (:mod:`companion.reasoning.onboard` and :mod:`companion.reasoning.net_judge`),
so that neither imports the other for them."""

from __future__ import annotations

from dataclasses import dataclass

from companion.config_schema import DEFAULTS

__all__ = ["ConfirmParams", "GeometryWeights"]


@dataclass(frozen=True, slots=True)
class GeometryWeights:
    """How Surface ID's geometry scores a candidate (points, comparable to image-cue hazard points)."""

    area: float = 1.5  # at area_full_m2 of landable area or more
    area_full_m2: float = 400.0  # beyond this a site is not safer, only bigger (Surface ID's score_area_m2)
    edge: float = 1.0  # at edge_full_m from the nearest edge or more
    edge_full_m: float = 8.0
    slope_per_deg: float = 0.15  # lost per degree over slope_free_deg
    slope_free_deg: float = 2.0
    roughness_per_cm: float = 0.25  # lost per centimetre over roughness_free_m
    roughness_free_m: float = 0.02
    roof_height_m: float = 3.0  # this far above its surroundings: a roof (Surface ID's roof_height_m)
    elevated: float = 2.0  # a roof: away from traffic and people
    street_level: float = -1.0  # streets, plazas, car parks: traffic comes back
    extended: float = 0.5  # lost at measured_share 0 (area the image extended, no depth behind it)
    crop_size: float = 0.3  # images only: for the largest crop of the request (sqrt of the pixel share)


@dataclass(frozen=True, slots=True)
class ConfirmParams:
    """When the onboard tier says yes to a close-up (module docstring)."""

    max_hazard: float = 1.0  # total site hazard; 0.5 is a fully asphalt-like (tar) roof, alone no reason
    max_hazard_critical: float = 1.6
    max_raised: int = 0  # raised objects on the site (people, vehicles, clutter)
    max_raised_critical: int = 1  # ... with a critical alarm and a clear LiDAR check
    max_water: float = 0.1  # share of the site (or right beside it)
    max_vegetation: float = 0.15
    max_markings: float = 0.3  # total lane-marking length, in working-image diagonals (about one line)
    max_raised_lines: float = 0.3  # pipes, rails
    max_street_asphalt: float = 0.5  # asphalt-like share of a site measured at street level: road, car park
    # open ground among buildings (a lawn, a sports field, a pasture: net_judge): a grass surface at least
    # this large and the site at least this far from its edge (the road, path or fence where people pass)
    open_ground_area_m2: float = DEFAULTS.reasoner.open_ground_area_m2
    open_ground_edge_m: float = DEFAULTS.reasoner.open_ground_edge_m
    site_window: float | None = None  # share of each side judged; None: by the image's shape (image_cues)
