"""The report's PNG figures (matplotlib, the ``bench`` extra): the bird's-eye map per scenario, a
failure's thumbnail, surfaces per reasoner, the rounds histogram, the rationale clusters."""

from __future__ import annotations

import logging
import math
from collections import Counter, defaultdict
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from landfall_eval.basemap import CLASS_LABEL, CLASS_RGB, BaseMap, basemap
from landfall_eval.grading import SURFACES
from landfall_eval.rationales import Clusters
from landfall_eval.study import (
    STUDY_ROUNDS_PER_SAFE,
)
from simbridge.world.model import SurfaceClass

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

from landfall_eval.report.episodes import INSTALL_HINT, Episode, MatplotlibUnavailable, as_number
from landfall_eval.report.markup import escape

log = logging.getLogger("landfall_eval.report")


VERDICT_COLOUR = {"safe": "#12a150", "unsafe": "#e02424", "none": "#6b7280"}


VERDICT_LABEL = {"safe": "safe landing", "unsafe": "unsafe landing", "none": "no landing / timeout / error"}


MAP_MARGIN_M = 60.0


MAP_MIN_SIDE_M = 200.0


MAP_MAX_PX = 1400


THUMB_HALF_M = 30.0  # a failure's thumbnail: the 60 m square around its touchdown


MAP_MAX_LABELS = 40  # number the touchdowns (as in the episode table) up to this many episodes


DPI = 110


def new_figure(
    width_in: float, height_in: float, layout: Literal["constrained"] | None = "constrained"
) -> Figure:
    try:
        from matplotlib.figure import Figure
    except ImportError as exc:
        raise MatplotlibUnavailable(f"the companion-bench report needs matplotlib: {INSTALL_HINT}") from exc
    # no pyplot: a bare Figure renders with Agg and touches no global backend state
    return Figure(figsize=(width_in, height_in), layout=layout)


def save_figure(fig: Figure, path: Path) -> None:
    fig.savefig(path, dpi=DPI, bbox_inches="tight", pad_inches=0.15)  # legends outside the axes included


def cache_of(config: Mapping[str, Any]) -> Path | None:
    """The campaign's place cache (``config.world_cache``), where it still exists."""
    given = config.get("world_cache")
    return Path(given) if isinstance(given, str) and Path(given).is_dir() else None


def map_figure(
    scenario: str, eps: list[Episode], config: Mapping[str, Any], bm: BaseMap | None, path: Path
) -> list[str]:
    """Draw one scenario's map; returns the notes and warnings for the page, as HTML paragraphs
    (none when all went as planned)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    bounds = map_bounds(eps)
    note = ""
    seed = world_seed(scenario, eps, config)
    if bm is None:
        try:
            place = str(config.get("place", "downtown"))
            bm = basemap(scenario, seed, bounds, max_px=MAP_MAX_PX, place=place, world_cache=cache_of(config))
        except ValueError as exc:  # an unknown scenario, or bounds outside its world
            log.warning("no background for the %s map: %s", scenario, exc)
            note = f"No background map: {exc}"
    warning = world_mismatch(scenario, seed, eps, bm)
    aspect = (bounds[3] - bounds[2]) / (bounds[1] - bounds[0])
    # no layout engine: it squeezes a fixed-aspect map with a tall legend; the tight bbox frames it all
    fig = new_figure(min(max(8.0 * aspect, 4.0), 14.0), 8.0, layout=None)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    surface: list[Any] = []
    if bm is not None:
        ax.imshow(bm.rgb, extent=bm.imshow_extent, origin="upper", interpolation="nearest", alpha=0.8)
        surface = [
            Patch(color=rgb01(CLASS_RGB[c]), label=CLASS_LABEL[c]) for c in visible_classes(bm, bounds)
        ]
    draw_episodes(ax, eps, label=len(eps) <= MAP_MAX_LABELS)
    ax.set(xlim=bounds[2:], ylim=bounds[:2], aspect="equal", xlabel="east (m)", ylabel="north (m)")
    counts = Counter(e.verdict for e in eps)
    ax.set_title(f"{scenario}, world seed {seed}: {len(eps)} episodes")
    verdicts = [
        Line2D([], [], marker="o" if v != "none" else "X", color=VERDICT_COLOUR[v], mec="black", ms=8,
               label=f"{VERDICT_LABEL[v]} ({counts[v]})")
        for v in ("safe", "unsafe", "none")
    ]  # fmt: skip
    launch = Line2D([], [], marker="^", ls="", mfc="white", mec="black", ms=10, label="launch")
    # one legend, right of the map: a legend inside would hide episodes near the corners
    header = Line2D([], [], ls="", label="surface")
    legend = ax.legend(handles=[launch, *verdicts, *([header, *surface] if surface else [])],
                       loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)  # fmt: skip
    if surface:
        legend.get_texts()[len(verdicts) + 1].set_fontweight("bold")
    save_figure(fig, path)
    lines = (("warning", warning), ("note", note))
    return [f'<p class="{cls}">{escape(text)}</p>' for cls, text in lines if text]


def world_mismatch(scenario: str, seed: int, eps: list[Episode], bm: BaseMap | None) -> str:
    """A warning when episodes that should have flown the mapped world flew another (their
    ``world_digest`` differs from the map's): every episode of a city (one campaign, one city),
    those of a scenario file whose seed is the map's (its furniture follows the seed). '' when all
    agree or the digests are unknown."""
    if bm is None or bm.world_digest is None:
        return ""
    meant = [e for e in eps if e.world_digest is not None and (scenario == "city" or e.seed == seed)]
    other = [e for e in meant if e.world_digest != bm.world_digest]
    if not other:
        return ""
    digests = ", ".join(sorted({str(e.world_digest) for e in other})[:3])
    numbers = ", ".join(f"#{e.number}" for e in other[:10]) + (", ..." if len(other) > 10 else "")
    what = f"city seed {seed}" if scenario == "city" else f"seed {seed}"
    return (
        f"Warning: this map is the {scenario} of {what} (world digest {bm.world_digest}), but "
        f"{len(other)} of {len(meant)} episodes flew another world (digest {digests}; episodes {numbers}): "
        "their tracks are drawn over a world they did not fly."
    )


def map_bounds(eps: list[Episode]) -> tuple[float, float, float, float]:
    """(north_min, north_max, east_min, east_max) around every point drawn, with a margin."""
    pts = [p for e in eps for p in (e.launch_ne, e.touchdown_ne) if p is not None]
    arr = np.concatenate([np.array(pts, np.float64).reshape(-1, 2), *(e.track_ne for e in eps)])
    if not len(arr):
        arr = np.zeros((1, 2))
    (n0, e0), (n1, e1) = arr.min(axis=0) - MAP_MARGIN_M, arr.max(axis=0) + MAP_MARGIN_M
    # at least MAP_MIN_SIDE_M a side, so a lone episode still shows its neighbourhood
    cn, ce = (n0 + n1) / 2, (e0 + e1) / 2
    half_n, half_e = max(n1 - n0, MAP_MIN_SIDE_M) / 2, max(e1 - e0, MAP_MIN_SIDE_M) / 2
    return (float(cn - half_n), float(cn + half_n), float(ce - half_e), float(ce + half_e))


def draw_episodes(ax: Axes, eps: list[Episode], *, label: bool) -> None:
    """Each episode's track (thin), launch-to-touchdown arrow, touchdown and launch markers."""
    from matplotlib import patheffects

    halo = [patheffects.withStroke(linewidth=2.5, foreground="white")]
    for e in eps:
        colour = VERDICT_COLOUR[e.verdict]
        if len(e.track_ne):
            ax.plot(e.track_ne[:, 1], e.track_ne[:, 0], color=colour, lw=1.0, alpha=0.7, zorder=3)
        end = e.touchdown_ne or (tuple(e.track_ne[-1]) if len(e.track_ne) else None)
        if end is None:
            continue
        if e.launch_ne is not None and e.verdict != "none":
            arrow = {"arrowstyle": "-|>", "color": colour, "lw": 1.8, "shrinkA": 0, "shrinkB": 4,
                     "mutation_scale": 14, "alpha": 0.9}  # fmt: skip
            ax.annotate(
                "", xy=(end[1], end[0]), xytext=(e.launch_ne[1], e.launch_ne[0]), zorder=4, arrowprops=arrow
            )
        marker = "o" if e.verdict != "none" else "X"
        ax.scatter(
            [end[1]], [end[0]], s=70, marker=marker, c=colour, edgecolors="black", linewidths=1.0, zorder=6
        )
        if label:
            ax.annotate(f"{e.number}", (end[1], end[0]), xytext=(5, 4), textcoords="offset points",
                        fontsize=7, zorder=8, path_effects=halo)  # fmt: skip
    launches = np.array([e.launch_ne for e in eps if e.launch_ne is not None]).reshape(-1, 2)
    ax.scatter(
        launches[:, 1],
        launches[:, 0],
        s=110,
        marker="^",
        c="white",
        edgecolors="black",
        linewidths=1.4,
        zorder=7,
    )


def visible_classes(bm: BaseMap, bounds: tuple[float, float, float, float]) -> list[SurfaceClass]:
    """Classes with at least 0.2 % of the pixels inside ``bounds``, most first."""
    n0, n1, e0, e1 = bounds
    _, top, west, _ = bm.extent_ne_m
    rows, cols = bm.cls.shape
    r0, r1 = max(0, math.floor((top - n1) / bm.px_m)), min(rows, math.ceil((top - n0) / bm.px_m))
    c0, c1 = max(0, math.floor((e0 - west) / bm.px_m)), min(cols, math.ceil((e1 - west) / bm.px_m))
    part = bm.cls[r0:r1, c0:c1]
    if part.size == 0:
        return []
    counts = np.bincount(part.ravel(), minlength=256)
    known = {int(c) for c in SurfaceClass}
    order = np.argsort(-counts, kind="stable")
    return [SurfaceClass(int(k)) for k in order if int(k) in known and counts[k] >= 0.002 * part.size]


def rgb01(rgb: tuple[int, int, int]) -> tuple[float, float, float]:
    return (rgb[0] / 255, rgb[1] / 255, rgb[2] / 255)


def world_seed(scenario: str, eps: list[Episode], config: Mapping[str, Any]) -> int:
    """The seed of the world to draw: a city's city seed (the run's, else its episodes' most common),
    a scenario file's first episode seed (its furniture follows the episode seed)."""
    if scenario == "city":
        if (s := as_number(config.get("city_seed"))) is not None:
            return int(s)
        seeds = Counter(e.city_seed for e in eps if e.city_seed is not None)
        return seeds.most_common(1)[0][0] if seeds else 0
    return next((e.seed for e in eps if e.seed is not None), 0)


def surface_figure(eps: list[Episode], path: Path) -> None:
    from matplotlib.patches import Patch

    groups: dict[tuple[str, str], list[Episode]] = defaultdict(list)
    for e in eps:
        groups[e.group].append(e)
    classes = list(SURFACES) + sorted({e.surface for e in eps} - set(SURFACES))
    fig = new_figure(11.0, 4.8)
    ax = fig.add_subplot()
    x = np.arange(len(classes))
    width = 0.8 / len(groups)
    colours = colour_cycle(len(groups))
    handles: list[Any] = []
    for g, (key, members) in enumerate(sorted(groups.items())):
        n = len(members)
        safe = np.array([sum(e.surface == c and e.verdict == "safe" for e in members) / n for c in classes])
        other = np.array([sum(e.surface == c and e.verdict != "safe" for e in members) / n for c in classes])
        xs = x - 0.4 + width * (g + 0.5)
        ax.bar(xs, safe, width, color=colours[g], hatch="///", edgecolor="white", linewidth=0.0)
        ax.bar(xs, other, width, bottom=safe, color=colours[g], alpha=0.35, edgecolor=colours[g])
        handles.append(Patch(color=colours[g], label=f"{key[0]} / {key[1]} ({n})"))
    handles += [
        Patch(facecolor="grey", hatch="///", edgecolor="white", label="safe landings"),
        Patch(facecolor="grey", alpha=0.35, label="unsafe or none"),
    ]
    ax.set_xticks(x, [c.replace("_", " ") for c in classes], rotation=30, ha="right")
    ax.set_ylabel("share of episodes")
    ax.set_ylim(0, 1.0)
    ax.set_title("Touchdown surface by reasoner / context")
    ax.legend(handles=handles, fontsize=8, loc="upper right")
    ax.grid(axis="y", alpha=0.3)
    save_figure(fig, path)


def rounds_figure(eps: list[Episode], path: Path) -> None:
    from matplotlib.ticker import MaxNLocator

    landed = [e.rounds for e in eps if e.verdict != "none" and e.rounds is not None]
    safe = [e.rounds for e in eps if e.verdict == "safe" and e.rounds is not None]
    fig = new_figure(7.5, 4.2)
    ax = fig.add_subplot()
    top = max(landed, default=1)
    bins = [k - 0.5 for k in range(top + 2)]
    ax.hist(landed, bins=bins, color="#93c5fd", label=f"all landings ({len(landed)})", rwidth=0.85)
    ax.hist(safe, bins=bins, color=VERDICT_COLOUR["safe"], label=f"safe landings ({len(safe)})", rwidth=0.55)
    if safe:
        ax.axvline(
            float(np.mean(safe)), color="black", ls="--", lw=1, label=f"mean, safe: {np.mean(safe):.2f}"
        )
    ax.axvline(
        STUDY_ROUNDS_PER_SAFE, color="#b45309", ls=":", lw=1.5, label=f"study: {STUDY_ROUNDS_PER_SAFE}"
    )
    ax.set_xticks(range(top + 1))
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("reasoning rounds")
    ax.set_ylabel("episodes")
    ax.legend(fontsize=8)
    save_figure(fig, path)


def cluster_figure(cl: Clusters, stages: list[str], path: Path) -> None:
    """PCA points coloured by cluster, shaped by stage, sized by how often the same text came back."""
    from matplotlib.lines import Line2D

    fig = new_figure(8.5, 6.0)
    ax = fig.add_subplot()
    colours = colour_cycle(len(cl.clusters))
    markers = {"rank": "o", "confirm": "^"}
    seen = Counter(zip(cl.texts, stages, strict=True))
    drawn: dict[tuple[str, str], tuple[float, float, int]] = {}
    for text, stage, (x, y), lab in zip(cl.texts, stages, cl.points_2d, cl.labels, strict=True):
        drawn[(text, stage)] = (float(x), float(y), int(lab))
    for (text, stage), (x, y, lab) in drawn.items():
        size = 30.0 * math.sqrt(seen[(text, stage)])
        ax.scatter([x], [y], s=size, c=[colours[lab]], marker=markers.get(stage, "s"), alpha=0.75,
                   edgecolors="black", linewidths=0.4)  # fmt: skip
    for c in cl.clusters:
        members = cl.points_2d[cl.labels == c.label]
        anchor = members[np.argmin(np.linalg.norm(members - members.mean(axis=0), axis=1))]
        ax.annotate(f"C{c.label + 1}", tuple(anchor), fontsize=11, weight="bold", color=colours[c.label],
                    xytext=(7, 7), textcoords="offset points")  # fmt: skip
    handles: list[Any] = [
        Line2D([], [], ls="", marker="o", color=colours[c.label], label=f"C{c.label + 1} ({c.size})")
        for c in cl.clusters
    ]
    handles += [
        Line2D([], [], ls="", marker=markers.get(s, "s"), mfc="white", mec="black", label=s)
        for s in sorted(set(stages))
    ]
    ax.legend(handles=handles, fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.set(
        xlabel="PCA 1",
        ylabel="PCA 2",
        title="Rationales: sentence-embedding clusters (bigger marker: repeated text)",
    )
    ax.margins(0.12)
    save_figure(fig, path)


def colour_cycle(n: int) -> list[Any]:
    from matplotlib import colormaps

    cmap: Callable[[int], Any] = colormaps["tab10"]
    return [cmap(i % 10) for i in range(max(n, 1))]


def thumbnail(e: Episode, config: Mapping[str, Any], path: Path) -> bool:
    """The 60 m around ``e``'s touchdown over its world's ground truth, the touchdown marked; False
    when the world cannot be drawn (the figure is then left out)."""
    assert e.touchdown_ne is not None
    n, east = e.touchdown_ne
    half = THUMB_HALF_M
    seed = e.city_seed if e.city_seed is not None else world_seed(e.scenario, [e], config)
    try:
        bounds = (n - half, n + half, east - half, east + half)
        place = str(config.get("place", "downtown"))
        bm = basemap(e.scenario, seed, bounds, max_px=240, place=place, world_cache=cache_of(config))
    except ValueError as exc:
        log.warning("no thumbnail for %s: %s", e.id, exc)
        return False
    fig = new_figure(2.6, 2.6, layout=None)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.imshow(bm.rgb, extent=bm.imshow_extent, origin="upper", interpolation="nearest")
    if len(e.track_ne):
        ax.plot(e.track_ne[:, 1], e.track_ne[:, 0], "-", color="white", lw=1.2)
    ax.plot([east], [n], marker="X", ms=11, color=VERDICT_COLOUR[e.verdict], mec="black")
    ax.set(xlim=(east - half, east + half), ylim=(n - half, n + half), aspect="equal", xticks=[], yticks=[])
    save_figure(fig, path)
    return True
