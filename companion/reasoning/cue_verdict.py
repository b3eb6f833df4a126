"""What the image cues amount to: :class:`ImageCues`, the measurements of one image
(:func:`companion.reasoning.image_cues.analyse`), with the hazard they add up to (:func:`scored`) and
the short phrases that name what was seen, for a rationale and the flight record (``to_json``)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from companion.reasoning.cue_params import CueParams

__all__ = ["ImageCues", "scored"]


@dataclass(frozen=True, slots=True)
class ImageCues:
    """Measured cues of one image. Shares are fractions (0..1) of the image, or of the site."""

    size_px: tuple[int, int]  # (height, width) of the image as given
    work_px: tuple[int, int]  # (height, width) it was analysed at (the window, in site mode)
    site_share: float  # share of the analysed window judged (1.0 unless site mode)
    brightness: float  # median luminance, 0..1
    contrast: float  # the contrast unit c (luminance, 0..1)
    grain: float  # relative amplitude of the fine texture
    uniform_grain: bool  # the grain is visible and spread evenly: gravel, tiles, shingles
    edge_density: float  # share of pixels on an edge at the working scale
    edge_spread_cv: float  # its coefficient of variation over 4 x 4 blocks
    shadow_share: float
    water_share: float
    vegetation_share: float
    asphalt_share: float
    raised_blobs: int  # compact objects next to a shadow (or their own side wall)
    raised_share: float
    coloured_blobs: int  # raised objects of a saturated colour unlike the surface (cars, people)
    shadow_blobs: int  # compact shadows with no object beside them: something stands there unseen
    flat_blobs: int  # compact patches casting no shadow (paint, stains)
    flat_share: float
    dark_blobs: int  # compact objects darker than any shadow, casting none
    lane_lines: int  # straight thin near-white lines casting no shadow (paint)
    line_length: float  # their total length, in working-image diagonals
    raised_lines: int  # straight thin lines casting a shadow (pipes, rails)
    raised_line_length: float
    other_surface_share: float  # components too large to be objects: another surface in view
    hazard: float
    terms: tuple[tuple[str, float], ...]  # the hazard's non-zero terms, largest first
    # what it was measured with: its words use the same thresholds
    params: CueParams = field(default_factory=CueParams, repr=False, compare=False)

    @property
    def road(self) -> bool:
        """Clear lane markings seen (``HazardWeights.road_markings``): a road, a highway or a car park."""
        return self.line_length >= self.params.weights.road_markings

    def term(self, name: str) -> float:
        return dict(self.terms).get(name, 0.0)

    def observations(self) -> tuple[str, ...]:
        """Short phrases naming what was seen, hazards first (largest first), then what is not one."""
        out = [self.phrase(name) for name, _v in self.terms]
        if self.term("raised") == 0.0 and self.term("lines_raised") == 0.0:
            out.append("no clutter")
        if self.uniform_grain and self.term("road_texture") == 0.0:
            out.append(f"uniform {self._material()} texture (not a hazard)")
        if self.shadow_share >= 0.02:
            out.append(f"shadow {100 * self.shadow_share:.0f} % (not a hazard)")
        if self.contrast <= self.params.min_contrast and self.brightness > 0.55:
            out.append("low contrast (haze?)")
        return tuple(out)

    def phrase(self, name: str) -> str:
        """The observation naming one hazard term (a :class:`HazardWeights` weight's name)."""
        if name == "water":
            return f"water ({100 * self.water_share:.0f} %)"
        if name == "vegetation":
            return f"vegetation ({100 * self.vegetation_share:.0f} %)"
        if name == "markings":
            lines = "1 painted line" if self.lane_lines == 1 else f"{self.lane_lines} painted lines"
            return f"lane markings ({lines}: a road stays risky even when empty)"
        if name == "raised":
            # A few objects on a road are vehicles; many of them (clutter's share) are clutter, whatever
            # pipes running across them look like.
            few = self.raised_share < self.params.weights.raised_full
            what = "vehicle-like objects" if self.road and few else "HVAC-like blobs"
            seen = self.raised_blobs - self.shadow_blobs
            if self.shadow_blobs == 0:
                return f"{what} with shadows ({seen})"
            unseen = f"compact shadows of unseen objects ({self.shadow_blobs})"
            return unseen if seen == 0 else f"{what} with shadows ({seen}) and {unseen}"
        if name == "coloured":
            return f"coloured objects with shadows ({self.coloured_blobs}: vehicles or people?)"
        if name == "lines_raised":
            return f"pipes or rails casting shadows ({self.raised_lines})"
        if name == "flat_blobs":
            return f"flat patches without shadows ({self.flat_blobs}: paint or stains)"
        if name == "dark_blobs":
            return f"dark objects ({self.dark_blobs})"
        if name == "asphalt":
            return f"dark asphalt-like surface ({100 * self.asphalt_share:.0f} %)"
        if name == "road_texture":
            return "road texture (an even fine grain on the asphalt)"
        return f"busy edges ({100 * self.edge_density:.0f} %)"

    def _material(self) -> str:
        return "gravel or tile" if self.brightness > 0.35 else "dark"

    def to_json(self) -> dict[str, Any]:
        return {
            "size_px": list(self.size_px),
            "work_px": list(self.work_px),
            "site_share": round(self.site_share, 4),
            "brightness": round(self.brightness, 3),
            "contrast": round(self.contrast, 4),
            "grain": round(self.grain, 4),
            "uniform_grain": self.uniform_grain,
            "edge_density": round(self.edge_density, 4),
            "edge_spread_cv": round(self.edge_spread_cv, 3),
            "shares": {
                "shadow": round(self.shadow_share, 4),
                "water": round(self.water_share, 4),
                "vegetation": round(self.vegetation_share, 4),
                "asphalt": round(self.asphalt_share, 4),
                "raised": round(self.raised_share, 4),
                "flat": round(self.flat_share, 4),
                "other_surface": round(self.other_surface_share, 4),
            },
            "counts": {
                "raised_blobs": self.raised_blobs,
                "coloured_blobs": self.coloured_blobs,
                "shadow_blobs": self.shadow_blobs,
                "flat_blobs": self.flat_blobs,
                "dark_blobs": self.dark_blobs,
                "lane_lines": self.lane_lines,
                "raised_lines": self.raised_lines,
            },
            "line_length": round(self.line_length, 3),
            "raised_line_length": round(self.raised_line_length, 3),
            "hazard": round(self.hazard, 3),
            "terms": {k: round(v, 3) for k, v in self.terms},
            "observations": list(self.observations()),
        }


def scored(cues: ImageCues) -> ImageCues:
    """``cues`` with its hazard: the weighted sum of its terms (:class:`HazardWeights`), each capped at
    its weight, the terms under ``min_term`` dropped, the rest largest first."""
    p, wt = cues.params, cues.params.weights
    road_grain = cues.asphalt_share >= 0.5 and cues.grain >= p.road_grain
    raised = max(cues.raised_share / wt.raised_full, cues.raised_blobs / wt.raised_count_full)
    clustered = 0.0 if cues.edge_spread_cv < p.edge_cv_texture else cues.edge_density
    values = {
        "water": wt.water * min(1.0, cues.water_share / wt.water_full),
        "vegetation": wt.vegetation * min(1.0, cues.vegetation_share / wt.vegetation_full),
        "markings": wt.markings * min(1.0, cues.line_length / wt.markings_full),
        "raised": wt.raised * min(1.0, raised),
        "coloured": wt.coloured * min(1.0, cues.coloured_blobs / wt.coloured_full),
        "lines_raised": wt.lines_raised * min(1.0, cues.raised_line_length / wt.lines_raised_full),
        "dark_blobs": wt.dark_blobs * min(1.0, cues.dark_blobs / wt.dark_full),
        "flat_blobs": wt.flat_blobs * min(1.0, cues.flat_share / wt.flat_blobs_full),
        "asphalt": wt.asphalt * min(1.0, cues.asphalt_share),
        "road_texture": wt.road_texture * cues.asphalt_share * (cues.uniform_grain and road_grain),
        "edges": wt.edges * min(1.0, clustered / wt.edges_full),
    }
    kept = [(k, float(v)) for k, v in values.items() if v >= wt.min_term]
    terms = tuple(sorted(kept, key=lambda kv: -kv[1]))
    return replace(cues, hazard=float(sum(v for _k, v in terms)), terms=terms)
