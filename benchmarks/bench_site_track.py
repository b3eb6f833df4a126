"""How well the site is found again: ``track_site``'s error against the truth, over simbridge's renders.

The companion finds its chosen site again in each newer frame by matching it against an older one
(companion/perception/site_track.py). This measures that match alone, with every pose exact: the
reference frame from high up and off to one side (as a site is chosen, up to 40 m beside the
vehicle), the newer one from 40, 17 or 8 m nearly over the site, tilted and turned a little. The site
is a point on a flat roof, some in the middle of a roof and some 3 m from its edge, picked from the
world's ground truth; what the match returns is compared with where it truly is.

    python benchmarks/bench_site_track.py [--worlds scenario1,scenario2,city] [--sites 6] [--json OUT]

Prints, per world and in all: the looks found, and the error of those found (median, 90th
percentile, largest, metres). The sites, poses and renders come from fixed seeds: two runs of one
commit print the same figures.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections import Counter
from pathlib import Path

import numpy as np

from companion.guidance.frames import PinholeCamera
from companion.perception.site_track import NOT_IN_REFERENCE, OUT_OF_VIEW, SiteView, track_site
from simbridge.geo import euler_to_quat
from simbridge.scenarios import load_scenario
from simbridge.world.live import LiveWorld
from simbridge.world.model import SurfaceClass

REF_UP_M = 85.0  # the reference frame's height above the roof
REF_ASIDE_M = (0.0, 20.0, 40.0)  # ... and how far beside the site
CUR_UP_M = (40.0, 17.0, 8.0)  # the newer frame's height above the roof


def _roof_sites(w: LiveWorld, n: int, rng: np.random.Generator) -> list[np.ndarray]:
    """``n`` points on flat roofs at least 25 m above the ground: half well inside a roof (8 m or
    more from anything else), half about 3 m from its edge."""
    from scipy import ndimage

    g = w.grid
    flat = g.cls == SurfaceClass.ROOF_FLAT
    inside = ndimage.distance_transform_edt(flat) * g.res
    high = g.height >= 25.0
    picks: list[np.ndarray] = []
    for lo, hi in ((8.0, 1e9), (2.5, 3.5)):
        rows, cols = np.nonzero(flat & high & (inside >= lo) & (inside < hi))
        if rows.size == 0:
            continue
        for k in rng.choice(rows.size, size=min(n - n // 2 if lo > 5 else n // 2, rows.size), replace=False):
            i, j = int(rows[k]), int(cols[k])
            picks.append(
                np.array([g.n0 + (i + 0.5) * g.res, g.e0 + (j + 0.5) * g.res, -float(g.height[i, j])])
            )
    return picks


def _view(w: LiveWorld, pos: tuple[float, float, float], quat: tuple[float, float, float, float]) -> SiteView:
    cam = w.camera
    camera = PinholeCamera.from_hfov(cam.width_px, cam.height_px, cam.hfov_deg)
    rgb = w.camera_frame(pos, quat, 0.0, "clear", np.random.default_rng(7)).rgb
    return SiteView(rgb, camera, pos, quat)


Look = tuple[float, str, float, float]  # error (m; NaN: refused), why refused, reference aside, newer up


def measure(w: LiveWorld, sites: list[np.ndarray], rng: np.random.Generator) -> list[Look]:
    """Each site's looks: its error in metres (NaN where the match refused), the refusal's reason, how
    far aside the reference was and how high the newer view (a reference that does not show the site,
    or a newer view that does not, is no look)."""
    errors: list[Look] = []
    for site in sites:
        for aside in REF_ASIDE_M:
            bearing = rng.uniform(0.0, 2.0 * math.pi)
            ref_pos = (
                site[0] + aside * math.cos(bearing),
                site[1] + aside * math.sin(bearing),
                site[2] - REF_UP_M,
            )
            ref = _view(w, ref_pos, euler_to_quat(0.0, 0.0, rng.uniform(-math.pi, math.pi)))
            for up in CUR_UP_M:
                pos = (site[0] + rng.normal(0, 0.5), site[1] + rng.normal(0, 0.5), site[2] - up)
                q = euler_to_quat(rng.normal(0, 0.03), rng.normal(0, 0.03), rng.uniform(-math.pi, math.pi))
                result = track_site(ref, tuple(site), _view(w, pos, q))
                if result.reason in (NOT_IN_REFERENCE, OUT_OF_VIEW):
                    continue  # not a look the companion would make
                err = math.dist(result.site_ned_m[:2], site[:2]) if result.found else math.nan
                errors.append((err, result.reason, aside, up))
    return errors


def summary(looks: list[Look]) -> dict[str, object]:
    e = np.asarray([x[0] for x in looks], dtype=np.float64)
    ok = e[np.isfinite(e)]
    refused = Counter(x[1] for x in looks if not math.isfinite(x[0]))
    out: dict[str, object] = {"looks": int(e.size), "found": int(ok.size)}
    out["refused"] = dict(refused.most_common())
    if ok.size:
        out |= {
            "median_m": round(float(np.median(ok)), 3),
            "p90_m": round(float(np.percentile(ok, 90)), 3),
            "max_m": round(float(ok.max()), 3),
        }
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", default="scenario1,scenario2,city", help="scenarios (city: city 0, downtown)")
    ap.add_argument("--sites", type=int, default=6, help="sites per world (half near a roof's edge)")
    ap.add_argument("--json", type=Path, help="write the figures here too")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows: dict[str, dict[str, object]] = {}
    every: list[Look] = []
    for k, name in enumerate(args.worlds.split(",")):
        w = load_scenario(name, 0).terrain
        if not isinstance(w, LiveWorld):
            raise SystemExit(f"{name}: no rendered world")
        rng = np.random.default_rng(100 + k)
        errors = measure(w, _roof_sites(w, args.sites, rng), rng)
        rows[name] = summary(errors)
        every += errors
        print(name, json.dumps(rows[name]), flush=True)
    rows["all"] = summary(every)
    print("all", json.dumps(rows["all"]), f"({time.perf_counter() - t0:.0f} s)")
    for aside in REF_ASIDE_M:
        for up in CUR_UP_M:
            key = f"reference {aside:.0f} m aside, newer view {up:.0f} m up"
            rows[key] = summary([x for x in every if x[2] == aside and x[3] == up])
            print(key, json.dumps({k: v for k, v in rows[key].items() if k != "refused"}))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
