"""companion-bench's report: PNG figures and one HTML page from a results dict (``landfall-bench/1``).

:func:`write_report` writes ``out_dir/report.html`` and ``out_dir/figures/*.png``; the page links the
figures by relative path, so the folder can be moved or archived whole. Every section is optional: a
run with only the module checks, only episodes, or an empty episode list gives a page with what there
is. Every text taken from the results is HTML-escaped.

Figures: a bird's-eye map per scenario (the world's classes from simbridge's ground truth, each
episode's launch, track and touchdown, coloured by verdict), touchdown surfaces per (reasoner, context),
a histogram of reasoning rounds and the rationale clusters. Needs the ``bench`` extra (matplotlib; the
clusters also need the sentence-embedding model, and without it the page says so instead).
"""

from __future__ import annotations

import datetime as dt
import html
import importlib.util
import json
import logging
import math
import re
from collections import Counter, defaultdict
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from landfall_eval.basemap import CLASS_LABEL, CLASS_RGB, BaseMap, basemap
from landfall_eval.episode import describe_last_state
from landfall_eval.grading import SURFACES, failure_class
from landfall_eval.rationales import Clusters, EmbeddingsUnavailable, cluster_rationales
from landfall_eval.study import (
    STUDY_JACCARD,
    STUDY_LANDING_DISTANCE_M,
    STUDY_PEAK_RSS_MB,
    STUDY_ROUNDS_PER_SAFE,
    STUDY_SAFE_RATE,
)
from simbridge.world.model import SurfaceClass

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

log = logging.getLogger(__name__)

VERDICT_COLOUR = {"safe": "#12a150", "unsafe": "#e02424", "none": "#6b7280"}
VERDICT_LABEL = {"safe": "safe landing", "unsafe": "unsafe landing", "none": "no landing / timeout / error"}
_MAP_MARGIN_M = 60.0
_MAP_MIN_SIDE_M = 200.0
_MAP_MAX_PX = 1400
_THUMB_HALF_M = 30.0  # a failure's thumbnail: the 60 m square around its touchdown
_MAX_FAILURES_SHOWN = 12  # per class; the episode table has them all
_MAP_MAX_LABELS = 40  # number the touchdowns (as in the episode table) up to this many episodes
_DPI = 110
_INSTALL_HINT = "pip install 'landfall[bench]'"
_NA = "\N{EN DASH}"  # a missing figure in a table
_STATS, _STATS2 = ("mean", "min", "max"), ("mean", "median", "max")  # Jaccard, landing distance columns


class ReportError(RuntimeError):
    """The report cannot be written: a missing dependency or results that are not a results dict."""


class MatplotlibUnavailable(ReportError, ImportError):
    """matplotlib (the ``bench`` extra) is not installed."""


@dataclass(frozen=True, slots=True)
class _Episode:
    """The fields of one ``episodes[]`` entry the report uses, with missing values as None."""

    number: int  # 1-based position in the results' episode list
    id: str
    scenario: str
    seed: int | None
    city_seed: int | None
    world_digest: str | None  # the static world it flew (simbridge's episode log)
    group: tuple[str, str]  # (reasoner, context)
    weather: str
    launch_ne: tuple[float, float] | None
    touchdown_ne: tuple[float, float] | None
    track_ne: np.ndarray  # (k, 2) north, east metres
    surface: str
    safe: bool
    outcome: str
    error: str | None
    reasons: tuple[str, ...]
    rounds: int | None
    time_to_touchdown_s: float | None
    kinematic_ratio: float | None
    landing_distance_m: float | None  # true touchdown to what the chosen pixel truly shows
    peak_rss_mb: float | None
    calls: tuple[tuple[str, str, float | None], ...]  # (stage, tier, latency_s)
    rationales: tuple[tuple[str, str], ...]  # (stage, text)
    last_state: str  # where an episode that never landed stood at its end ('' when unknown)
    failure: str | None  # grading.failure_class: None for a safe landing

    @property
    def verdict(self) -> str:
        """``safe``, ``unsafe`` (landed, graded unsafe) or ``none`` (no landing, timeout, error)."""
        if self.outcome != "landed" or self.touchdown_ne is None or self.surface == "no_landing":
            return "none"
        return "safe" if self.safe else "unsafe"


def write_report(
    results: Mapping[str, Any], out_dir: Path, *, basemaps: Mapping[str, BaseMap] | None = None
) -> Path:
    """Write ``out_dir/report.html`` and its figures under ``out_dir/figures``.

    Args:
        results: a ``landfall-bench/1`` results dict (see the harness's docs); any key may be missing.
        out_dir: created if needed; existing files of the same names are replaced.
        basemaps: map backgrounds by scenario name, to skip building them (a city takes seconds);
            scenarios not in it are drawn from simbridge's ground truth.

    Returns:
        The path of ``report.html``.

    Raises:
        MatplotlibUnavailable: matplotlib is not installed.
        ReportError: ``results`` is not a mapping, or its ``episodes`` is not a list.
    """
    if importlib.util.find_spec("matplotlib") is None:
        raise MatplotlibUnavailable(f"the companion-bench report needs matplotlib: {_INSTALL_HINT}")
    if not isinstance(results, Mapping):
        raise ReportError(
            f"results must be a mapping (a landfall-bench/1 dict), got {type(results).__name__}"
        )
    raw_eps = results.get("episodes")
    if raw_eps is not None and not isinstance(raw_eps, list):
        raise ReportError(f"results['episodes'] must be a list, got {type(raw_eps).__name__}")
    config: Mapping[str, Any] = results.get("config") or {}
    if not isinstance(config, Mapping):
        raise ReportError(f"results['config'] must be a mapping, got {type(config).__name__}")
    episodes = [_episode(i, e, config) for i, e in enumerate(raw_eps or [], 1) if isinstance(e, Mapping)]
    fig_dir = out_dir / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)

    parts = [_header(results, config), _summary(results, episodes)]
    modules = results.get("modules")
    if isinstance(modules, Mapping) and modules:
        parts.append(_modules(modules))
    if raw_eps is not None:
        parts.append(_landings(episodes, config, fig_dir, basemaps or {}))
    if episodes:
        parts += [
            _latency(episodes),
            _weather(episodes),
            _failures(episodes, config, fig_dir),
            _clusters(episodes, fig_dir),
            _episode_table(episodes),
        ]
    page = _PAGE.format(
        title=_e(f"companion-bench: {results.get('command', 'results')}"), body="\n".join(parts)
    )
    path = out_dir / "report.html"
    path.write_text(page, encoding="utf-8")
    return path


def write_episode_report(entry: Mapping[str, Any], out_dir: Path, record_dir: Path | None = None) -> Path:
    """One episode's page (what the demo writes): the verdict, the trajectory over the map and, from
    the flight record in ``record_dir``, the drone's-eye frame of each round with the candidates
    boxed, the chosen one in green and the reasoner's rationale beside it, then each confirmation's
    close-up with its verdict. Returns the path of ``out_dir/report.html``.

    Raises:
        MatplotlibUnavailable: matplotlib is not installed.
    """
    from landfall_eval.rounds import rounds_html

    if importlib.util.find_spec("matplotlib") is None:
        raise MatplotlibUnavailable(f"the episode report needs matplotlib: {_INSTALL_HINT}")
    fig_dir = out_dir / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    ep = _episode(1, entry, {})
    rows = [
        ("scenario", ep.scenario),
        ("surface at touchdown", entry.get("surface", _NA)),
        ("safe", f"{entry.get('safe')} {'; '.join(_list(entry.get('reasons')))}".strip()),
        ("rounds", entry.get("rounds", _NA)),
        ("time from taking control to touchdown", _f(_num(entry.get("time_to_touchdown_s")), 1, " s")),
        ("over the kinematic lower bound", _f(_num(entry.get("kinematic_ratio")), 2, "x")),
    ]
    parts = [
        f"<h1>Landfall episode: {_e(entry.get('id', ep.scenario))}</h1>",
        _table(("", ""), rows),
        "<h2>Trajectory</h2>",
    ]
    notes = _map_figure(ep.scenario, [ep], {}, None, fig_dir / "map.png")
    parts.append(_img("map.png", f"bird's-eye map of {ep.scenario} with the trajectory"))
    parts += notes
    parts.append(rounds_html(record_dir, fig_dir) if record_dir is not None else "")
    page = _PAGE.format(title=_e(f"Landfall episode {entry.get('id', '')}"), body="\n".join(parts))
    path = out_dir / "report.html"
    path.write_text(page, encoding="utf-8")
    return path


# ---------------------------------------------------------------------------------------------- reading
def _episode(number: int, raw: Mapping[str, Any], config: Mapping[str, Any]) -> _Episode:
    launch, touchdown = _ne(raw.get("launch_ned_m")), _ne(raw.get("touchdown_ned_m"))
    track = np.array(
        [p for p in (_ne(q) for q in _list(raw.get("trajectory_ne_m"))) if p is not None], np.float64
    ).reshape(-1, 2)
    companion = _map(raw.get("companion"))
    rounds = _num(raw.get("rounds"))
    return _Episode(
        number=number,
        id=str(raw.get("id", "?")),
        scenario=str(raw.get("scenario", "?")),
        seed=int(s) if (s := _num(raw.get("seed"))) is not None else None,
        city_seed=int(c) if (c := _num(raw.get("city_seed"))) is not None else None,
        world_digest=d if isinstance(d := raw.get("world_digest"), str) else None,
        group=(
            str(raw.get("reasoner", config.get("reasoner", "?"))),
            str(raw.get("context", config.get("context", "?"))),
        ),
        weather=str(raw.get("weather", config.get("weather", "?"))),
        launch_ne=launch,
        touchdown_ne=touchdown,
        track_ne=track,
        surface=str(raw.get("surface") or "no_landing"),
        safe=raw.get("safe") is True,
        outcome=str(raw.get("outcome", "landed" if touchdown is not None else "error")),
        error=None if raw.get("error") is None else str(raw.get("error")),
        reasons=tuple(str(r) for r in _list(raw.get("reasons"))),
        rounds=None if rounds is None else int(rounds),
        time_to_touchdown_s=_num(raw.get("time_to_touchdown_s")),
        kinematic_ratio=_num(raw.get("kinematic_ratio")),
        landing_distance_m=_num(raw.get("landing_distance_m")),
        peak_rss_mb=_num(companion.get("peak_rss_mb")),
        calls=tuple(
            (str(c.get("stage", "?")), str(c.get("tier", "?")), _num(c.get("latency_s")))
            for c in _list(raw.get("calls"))
            if isinstance(c, Mapping)
        ),
        rationales=tuple(
            (str(r.get("stage", "?")), str(r["text"]))
            for r in _list(raw.get("rationales"))
            if isinstance(r, Mapping) and str(r.get("text") or "").strip()
        ),
        last_state=describe_last_state(raw.get("last_state")),
        failure=failure_class(raw),
    )


def _num(x: object) -> float | None:
    """A finite number as float; None for anything else (missing, text, bool, NaN)."""
    if isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x):
        return None
    return float(x)


def _ne(x: object) -> tuple[float, float] | None:
    if not isinstance(x, Sequence) or isinstance(x, str) or len(x) < 2:
        return None
    n, e = _num(x[0]), _num(x[1])
    return None if n is None or e is None else (n, e)


def _map(x: object) -> Mapping[str, Any]:
    return x if isinstance(x, Mapping) else {}


def _list(x: object) -> list[Any]:
    return x if isinstance(x, list) else []


# ---------------------------------------------------------------------------------------------- html
_PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>
body {{ font: 14px/1.45 system-ui, sans-serif; margin: 2em auto; max-width: 1200px; color: #1f2937; }}
table {{ border-collapse: collapse; margin: 0.6em 0 1.2em; }}
th, td {{ border: 1px solid #d1d5db; padding: 3px 8px; text-align: left; vertical-align: top; }}
th {{ background: #f3f4f6; }} td.n {{ text-align: right; font-variant-numeric: tabular-nums; }}
img {{ max-width: 100%; border: 1px solid #e5e7eb; }} .note {{ color: #6b7280; font-style: italic; }}
.warning {{ color: #b91c1c; font-weight: bold; }}
blockquote {{ margin: 0.2em 0 0.2em 1em; color: #374151; }}
</style></head><body>
{body}
</body></html>
"""


def _e(x: object) -> str:
    return html.escape(str(x), quote=True)


def _table(head: Sequence[str], rows: Iterable[Sequence[object]]) -> str:
    """An HTML table; cells are escaped, numbers (already formatted as text or not) right-aligned."""
    out = ["<table><tr>", *(f"<th>{_e(h)}</th>" for h in head), "</tr>"]
    for row in rows:
        cells = (
            f'<td class="n">{_e(c)}</td>'
            if isinstance(c, int | float) or _NUMERIC.match(str(c))
            else f"<td>{_e(c)}</td>"
            for c in row
        )
        out += ["<tr>", *cells, "</tr>"]
    out.append("</table>")
    return "".join(out)


_NUMERIC = re.compile(r"^[-+]?[\d.,]+( ?(%|s|m|MB|x))?$")


def _f(x: float | None, digits: int = 2, unit: str = "") -> str:
    return _NA if x is None else f"{x:.{digits}f}{unit}"


def _pct(x: float | None) -> str:
    return _NA if x is None else f"{100 * x:.1f} %"


def _median(xs: Iterable[float | None]) -> float | None:
    v = [x for x in xs if x is not None]
    return float(np.median(v)) if v else None


def _mean(xs: Iterable[float | None]) -> float | None:
    v = [x for x in xs if x is not None]
    return float(np.mean(v)) if v else None


def _img(name: str, alt: str) -> str:
    return f'<p><img src="figures/{_e(name)}" alt="{_e(alt)}"></p>'


def _header(results: Mapping[str, Any], config: Mapping[str, Any]) -> str:
    created = _num(results.get("created_unix_s"))
    when = (
        _NA
        if created is None
        else dt.datetime.fromtimestamp(created, dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    )
    out = [
        f"<h1>companion-bench report: {_e(results.get('command', 'results'))}</h1>",
        f"<p>created {_e(when)}, schema {_e(results.get('schema', _NA))}</p>",
    ]
    if config:
        rows = [(k, v if isinstance(v, str) else json.dumps(v)) for k, v in config.items()]
        out += ["<h2>Configuration</h2>", _table(("setting", "value"), rows)]
    return "\n".join(out)


def _summary(results: Mapping[str, Any], eps: list[_Episode]) -> str:
    given = _map(results.get("summary"))
    if eps:
        n = len(eps)
        safe = [e for e in eps if e.verdict == "safe"]
        safe_rate: float | None = len(safe) / n
        rounds_safe = _mean(None if e.rounds is None else float(e.rounds) for e in safe)
    elif given:
        n = int(_num(given.get("episodes")) or 0)  # 0 where the count is missing
        safe_rate, rounds_safe = _num(given.get("safe_rate")), _num(given.get("mean_rounds_safe"))
    else:
        return ""
    rss = [e.peak_rss_mb for e in eps if e.peak_rss_mb is not None]
    outcomes = Counter(e.outcome for e in eps)
    rows = [
        ("episodes", str(n), _NA),
        ("safe landings", _pct(safe_rate), f"{_pct(STUDY_SAFE_RATE)} (city-wide, its best model)"),
        ("mean reasoning rounds per safe landing", _f(rounds_safe), f"{STUDY_ROUNDS_PER_SAFE}"),
        ("median time to touchdown", _f(_median(e.time_to_touchdown_s for e in eps), 1, " s"), _NA),
        ("median time / kinematic lower bound", _f(_median(e.kinematic_ratio for e in eps), 2, " x"), _NA),
        (
            "landing distance to the chosen pixel's true point (median, mean)",
            f"{_f(_median(e.landing_distance_m for e in eps), 2, ' m')}, "
            f"{_f(_mean(e.landing_distance_m for e in eps), 2, ' m')}",
            " / ".join(f"{sc} {m:.2f} m" for sc, m in sorted(STUDY_LANDING_DISTANCE_M.items())),
        ),
        (
            "companion peak RSS (max, median)",
            f"{max(rss):.0f} MB, {np.median(rss):.0f} MB" if rss else _NA,
            f"{STUDY_PEAK_RSS_MB:.0f} MB (its pipeline)",
        ),
    ]
    if outcomes:
        rows.append(("outcomes", ", ".join(f"{k}: {v}" for k, v in sorted(outcomes.items())), _NA))
    out = ["<h2>Summary</h2>", _table(("", "this run", "reference study"), rows)]
    groups: dict[tuple[str, str, str], list[_Episode]] = defaultdict(list)
    for e in eps:
        groups[(e.scenario, *e.group)].append(e)
    if len(groups) > 1:
        grows = [
            (
                *key,
                len(g),
                _pct(sum(e.verdict == "safe" for e in g) / len(g)),
                _f(_mean(float(e.rounds) for e in g if e.verdict == "safe" and e.rounds is not None)),
                _f(_median(e.time_to_touchdown_s for e in g), 1, " s"),
            )
            for key, g in sorted(groups.items())
        ]
        head = ("scenario", "reasoner", "context", "episodes", "safe", "rounds / safe", "median time")
        out.append(_table(head, grows))
    return "\n".join(out)


def _modules(mod: Mapping[str, Any]) -> str:
    out = []
    sid = _map(mod.get("surface_id"))
    if sid:
        jaccard = _per_scenario(sid, [f"jaccard_{k}" for k in _STATS], _STATS, 3, "", STUDY_JACCARD)
        out += ["<h3>Surface ID: Jaccard index</h3>", jaccard]
    dist = _map(mod.get("landing_distance"))
    if not dist:  # the short form: the mean alone
        dist = {sc: {"mean_m": m} for sc, m in _map(mod.get("landing_distance_m")).items()}
    if dist:
        out += [
            "<h3>Landing distance (horizontal error at touchdown)</h3>",
            _per_scenario(dist, [f"{k}_m" for k in _STATS2], _STATS2, 2, " m", STUDY_LANDING_DISTANCE_M),
        ]
    rows = []
    for sc, by_ctx in sorted(_map(mod.get("reasoner")).items()):
        for ctx, r in sorted(_map(by_ctx).items()):
            r = _map(r)
            rates = ("rank_success", "confirm_accept_clear", "confirm_reject_cluttered")
            latencies = ("rank_latency_s_median", "confirm_latency_s_median")
            rows.append((sc, ctx, *(_pct(_num(r.get(k))) for k in rates), _f(_num(r.get("iterations")), 0),
                         *(_f(_num(r.get(k)), 3, " s") for k in latencies)))  # fmt: skip
    if rows:
        head = ("scenario", "context", "rank success", "confirm: accepts clear", "confirm: rejects cluttered",
                "runs", "rank latency (median)", "confirm latency (median)")  # fmt: skip
        out += ["<h3>Reasoner stage success per context level</h3>", _table(head, rows)]
    return "\n".join(["<h2>Modules</h2>", *out]) if out else ""


def _per_scenario(
    by_scenario: Mapping[str, Any],
    keys: Sequence[str],
    heads: Sequence[str],
    digits: int,
    unit: str,
    study: Mapping[str, float],
) -> str:
    """Statistics ``keys`` (columns ``heads``) per scenario, with the runs and the study's figure."""
    rows = []
    for sc, r in sorted(by_scenario.items()):
        r = _map(r)
        theirs = _num(r.get("study"))
        theirs = study.get(sc) if theirs is None else theirs
        stats = (_f(_num(r.get(k)), digits, unit) for k in keys)
        rows.append((sc, *stats, _f(_num(r.get("iterations")), 0), _f(theirs, digits, unit)))
    return _table(("scenario", *heads, "runs", "study"), rows)


def _landings(
    eps: list[_Episode], config: Mapping[str, Any], fig_dir: Path, basemaps: Mapping[str, BaseMap]
) -> str:
    out = ["<h2>Landings</h2>"]
    if not eps:
        return out[0] + '<p class="note">No episodes in this run.</p>'
    by_world: dict[tuple[str, int], list[_Episode]] = defaultdict(list)
    for e in eps:  # a map per world: a city per city seed
        by_world[(e.scenario, e.city_seed if e.city_seed is not None else -1)].append(e)
    several = len({s for s, _ in by_world}) < len(by_world)
    used: set[str] = set()
    for (scenario, city), group in sorted(by_world.items()):
        title = f"{scenario}, city seed {city}" if city >= 0 and several else scenario
        name = _unique(f"map_{_slug(title)}.png", used)
        bm = None if several else basemaps.get(scenario)
        notes = _map_figure(scenario, group, config if not several else {}, bm, fig_dir / name)
        out += [f"<h3>{_e(title)}</h3>", _img(name, f"bird's-eye map of {title}"), *notes]
    _surface_figure(eps, fig_dir / "surfaces.png")
    _rounds_figure(eps, fig_dir / "rounds.png")
    out += [
        "<h3>Touchdown surfaces</h3>",
        _img("surfaces.png", "touchdown surface shares"),
        "<h3>Reasoning rounds</h3>",
        _img("rounds.png", "histogram of reasoning rounds"),
    ]
    return "\n".join(out)


def _failures(eps: list[_Episode], config: Mapping[str, Any], fig_dir: Path) -> str:
    """Every episode that did not end in a safe landing, by failure class (grading.failure_class),
    each with what it did and a thumbnail of its touchdown site over the world's ground truth."""
    by: dict[str, list[_Episode]] = defaultdict(list)
    for e in eps:
        if e.failure is not None:
            by[e.failure].append(e)
    out = ["<h2>Failures by class</h2>"]
    if not by:
        return out[0] + f'<p class="note">None: {len(eps)} of {len(eps)} episodes landed safely.</p>'
    out.append(_table(("class", "episodes", "share"), [
        (cls, len(g), _pct(len(g) / len(eps))) for cls, g in sorted(by.items(), key=lambda kv: -len(kv[1]))
    ]))  # fmt: skip
    used: set[str] = set()
    for cls, group in sorted(by.items(), key=lambda kv: -len(kv[1])):
        out.append(f'<h3>{_e(cls)} ({len(group)})</h3><ul class="failures">')
        for e in group[:_MAX_FAILURES_SHOWN]:
            thumb = ""
            if e.touchdown_ne is not None:
                name = _unique(f"touchdown_{_slug(e.id)}.png", used)
                if _thumbnail(e, config, fig_dir / name):
                    thumb = _img(name, f"touchdown site of {e.id}")
            what = "; ".join(e.reasons) if e.verdict == "unsafe" else (e.error or "")
            last = f" Last: {e.last_state}." if e.last_state and e.verdict == "none" else ""
            out.append(
                f"<li>{thumb}<b>#{e.number} {_e(e.id)}</b>: {_e(e.outcome)} on {_e(e.surface)} after "
                f"{e.rounds if e.rounds is not None else '?'} round(s). {_e(what)}{_e(last)}</li>"
            )
        if len(group) > _MAX_FAILURES_SHOWN:
            out.append(f"<li>... and {len(group) - _MAX_FAILURES_SHOWN} more (the episode table)</li>")
        out.append("</ul>")
    return "\n".join(out)


def _thumbnail(e: _Episode, config: Mapping[str, Any], path: Path) -> bool:
    """The 60 m around ``e``'s touchdown over its world's ground truth, the touchdown marked; False
    when the world cannot be drawn (the figure is then left out)."""
    assert e.touchdown_ne is not None
    n, east = e.touchdown_ne
    half = _THUMB_HALF_M
    seed = e.city_seed if e.city_seed is not None else _world_seed(e.scenario, [e], config)
    try:
        bm = basemap(e.scenario, seed, (n - half, n + half, east - half, east + half), max_px=240)
    except ValueError as exc:
        log.warning("no thumbnail for %s: %s", e.id, exc)
        return False
    fig = _figure(2.6, 2.6, layout=None)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.imshow(bm.rgb, extent=bm.imshow_extent, origin="upper", interpolation="nearest")
    if len(e.track_ne):
        ax.plot(e.track_ne[:, 1], e.track_ne[:, 0], "-", color="white", lw=1.2)
    ax.plot([east], [n], marker="X", ms=11, color=VERDICT_COLOUR[e.verdict], mec="black")
    ax.set(xlim=(east - half, east + half), ylim=(n - half, n + half), aspect="equal", xticks=[], yticks=[])
    _save(fig, path)
    return True


def _latency(eps: list[_Episode]) -> str:
    lat: dict[tuple[str, str], list[float | None]] = defaultdict(list)
    for e in eps:
        for stage, tier, s in e.calls:
            lat[(stage, tier)].append(s)
    if not lat:
        return '<h2>Reasoner latency</h2><p class="note">No reasoner calls recorded.</p>'
    stage_order = {"rank": 0, "confirm": 1}
    rows = []
    for (stage, tier), xs in sorted(lat.items(), key=lambda kv: (stage_order.get(kv[0][0], 2), kv[0])):
        v = [x for x in xs if x is not None]
        p90 = float(np.percentile(v, 90)) if v else None
        rows.append((stage, tier, len(xs), _f(_median(v), 3, " s"), _f(p90, 3, " s")))
    return "<h2>Reasoner latency</h2>" + _table(("stage", "tier", "calls", "median", "p90"), rows)


def _weather(eps: list[_Episode]) -> str:
    """Per weather; per city seed and weather as well when the run flew several cities."""
    cities = sorted({e.city_seed for e in eps if e.city_seed is not None})
    by: dict[str, list[_Episode]] = defaultdict(list)
    for e in eps:
        by[e.weather].append(e)
        if len(cities) > 1:
            by[f"city {e.city_seed}, {e.weather}"].append(e)
    rows = []
    for w, g in sorted(by.items(), key=lambda kv: (kv[0].startswith("city"), kv[0])):
        safe = [e for e in g if e.verdict == "safe"]
        rows.append(
            (
                w,
                len(g),
                len(safe),
                _pct(len(safe) / len(g)),
                _f(_mean(float(e.rounds) for e in safe if e.rounds is not None)),
                _f(_mean(float(e.rounds) for e in g if e.rounds is not None)),
            )
        )
    head = ("weather", "episodes", "safe", "safe rate", "mean rounds (safe landings)", "mean rounds (all)")
    return "<h2>Weather</h2>" + _table(head, rows)


def _clusters(eps: list[_Episode], fig_dir: Path) -> str:
    out = ["<h2>Rationale clusters</h2>"]
    items = [(stage, text) for e in eps for stage, text in e.rationales]
    if not items:
        return out[0] + '<p class="note">No rationales in this run.</p>'
    try:
        cl = cluster_rationales([t for _, t in items])
    except EmbeddingsUnavailable as exc:
        return out[0] + f'<p class="note">Rationale clusters not drawn: {_e(exc)}</p>'
    stages = [s for s, _ in items]
    _cluster_figure(cl, stages, fig_dir / "rationales.png")
    out += [
        f"<p>{len(items)} rationales from the rank and confirm stages, clustered together (k-means on "
        "all-MiniLM-L6-v2 sentence embeddings; the picture is their 2-D PCA projection; marker shape "
        "gives the stage).</p>",
        _img("rationales.png", "rationale clusters"),
        "<ol>",
    ]
    for c in cl.clusters:
        by_stage = Counter(s for s, lab in zip(stages, cl.labels, strict=True) if lab == c.label)
        mix = ", ".join(f"{s} {n}" for s, n in sorted(by_stage.items()))
        quotes = "".join(f"<blockquote>{_e(_short(t))}</blockquote>" for t in c.representatives)
        out.append(f"<li><b>C{c.label + 1}</b>: {c.size} rationales ({_e(mix)}){quotes}</li>")
    out.append("</ol>")
    return "\n".join(out)


def _episode_table(eps: list[_Episode]) -> str:
    rows = [
        (e.number, e.id, e.scenario, *e.group, e.weather, e.outcome, e.surface,
         "yes" if e.verdict == "safe" else "no", _f(None if e.rounds is None else float(e.rounds), 0),
         _f(e.time_to_touchdown_s, 1, " s"), _f(e.landing_distance_m, 2, " m"),
         "; ".join(e.reasons) + (f" (error: {e.error})" * bool(e.error))
         + (f" (last: {e.last_state})" * bool(e.verdict == "none" and e.last_state)))
        for e in eps
    ]  # fmt: skip
    head = ("#", "id", "scenario", "reasoner", "context", "weather", "outcome", "surface", "safe", "rounds",
            "time", "landing distance", "reasons")  # fmt: skip
    return (
        f"<h2>Episodes</h2><details open><summary>{len(eps)} episodes (# is the number on the maps)</summary>"
        f"{_table(head, rows)}</details>"
    )


def _short(text: str, limit: int = 240) -> str:
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _slug(s: str) -> str:
    return re.sub(r"[^A-Za-z0-9_-]+", "_", s).strip("_") or "scenario"


def _unique(name: str, used: set[str]) -> str:
    stem, k = name.removesuffix(".png"), 1
    while name in used:
        k += 1
        name = f"{stem}_{k}.png"
    used.add(name)
    return name


# ---------------------------------------------------------------------------------------------- figures
def _figure(
    width_in: float, height_in: float, layout: Literal["constrained"] | None = "constrained"
) -> Figure:
    try:
        from matplotlib.figure import Figure
    except ImportError as exc:
        raise MatplotlibUnavailable(f"the companion-bench report needs matplotlib: {_INSTALL_HINT}") from exc
    # no pyplot: a bare Figure renders with Agg and touches no global backend state
    return Figure(figsize=(width_in, height_in), layout=layout)


def _save(fig: Figure, path: Path) -> None:
    fig.savefig(path, dpi=_DPI, bbox_inches="tight", pad_inches=0.15)  # legends outside the axes included


def _map_figure(
    scenario: str, eps: list[_Episode], config: Mapping[str, Any], bm: BaseMap | None, path: Path
) -> list[str]:
    """Draw one scenario's map; returns the notes and warnings for the page, as HTML paragraphs
    (none when all went as planned)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    bounds = _map_bounds(eps)
    note = ""
    seed = _world_seed(scenario, eps, config)
    if bm is None:
        try:
            bm = basemap(scenario, seed, bounds, max_px=_MAP_MAX_PX)
        except ValueError as exc:  # an unknown scenario, or bounds outside its world
            log.warning("no background for the %s map: %s", scenario, exc)
            note = f"No background map: {exc}"
    warning = _world_mismatch(scenario, seed, eps, bm)
    aspect = (bounds[3] - bounds[2]) / (bounds[1] - bounds[0])
    # no layout engine: it squeezes a fixed-aspect map with a tall legend; the tight bbox frames it all
    fig = _figure(min(max(8.0 * aspect, 4.0), 14.0), 8.0, layout=None)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    surface: list[Any] = []
    if bm is not None:
        ax.imshow(bm.rgb, extent=bm.imshow_extent, origin="upper", interpolation="nearest", alpha=0.8)
        surface = [Patch(color=_rgb01(CLASS_RGB[c]), label=CLASS_LABEL[c]) for c in _visible(bm, bounds)]
    _draw_episodes(ax, eps, label=len(eps) <= _MAP_MAX_LABELS)
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
    _save(fig, path)
    lines = (("warning", warning), ("note", note))
    return [f'<p class="{cls}">{_e(text)}</p>' for cls, text in lines if text]


def _world_mismatch(scenario: str, seed: int, eps: list[_Episode], bm: BaseMap | None) -> str:
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


def _map_bounds(eps: list[_Episode]) -> tuple[float, float, float, float]:
    """(north_min, north_max, east_min, east_max) around every point drawn, with a margin."""
    pts = [p for e in eps for p in (e.launch_ne, e.touchdown_ne) if p is not None]
    arr = np.concatenate([np.array(pts, np.float64).reshape(-1, 2), *(e.track_ne for e in eps)])
    if not len(arr):
        arr = np.zeros((1, 2))
    (n0, e0), (n1, e1) = arr.min(axis=0) - _MAP_MARGIN_M, arr.max(axis=0) + _MAP_MARGIN_M
    # at least _MAP_MIN_SIDE_M a side, so a lone episode still shows its neighbourhood
    cn, ce = (n0 + n1) / 2, (e0 + e1) / 2
    half_n, half_e = max(n1 - n0, _MAP_MIN_SIDE_M) / 2, max(e1 - e0, _MAP_MIN_SIDE_M) / 2
    return (float(cn - half_n), float(cn + half_n), float(ce - half_e), float(ce + half_e))


def _draw_episodes(ax: Axes, eps: list[_Episode], *, label: bool) -> None:
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


def _visible(bm: BaseMap, bounds: tuple[float, float, float, float]) -> list[SurfaceClass]:
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


def _rgb01(rgb: tuple[int, int, int]) -> tuple[float, float, float]:
    return (rgb[0] / 255, rgb[1] / 255, rgb[2] / 255)


def _world_seed(scenario: str, eps: list[_Episode], config: Mapping[str, Any]) -> int:
    """The seed of the world to draw: a city's city seed (the run's, else its episodes' most common),
    a scenario file's first episode seed (its furniture follows the episode seed)."""
    if scenario == "city":
        if (s := _num(config.get("city_seed"))) is not None:
            return int(s)
        seeds = Counter(e.city_seed for e in eps if e.city_seed is not None)
        return seeds.most_common(1)[0][0] if seeds else 0
    return next((e.seed for e in eps if e.seed is not None), 0)


def _surface_figure(eps: list[_Episode], path: Path) -> None:
    from matplotlib.patches import Patch

    groups: dict[tuple[str, str], list[_Episode]] = defaultdict(list)
    for e in eps:
        groups[e.group].append(e)
    classes = list(SURFACES) + sorted({e.surface for e in eps} - set(SURFACES))
    fig = _figure(11.0, 4.8)
    ax = fig.add_subplot()
    x = np.arange(len(classes))
    width = 0.8 / len(groups)
    colours = _cycle(len(groups))
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
    _save(fig, path)


def _rounds_figure(eps: list[_Episode], path: Path) -> None:
    from matplotlib.ticker import MaxNLocator

    landed = [e.rounds for e in eps if e.verdict != "none" and e.rounds is not None]
    safe = [e.rounds for e in eps if e.verdict == "safe" and e.rounds is not None]
    fig = _figure(7.5, 4.2)
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
    _save(fig, path)


def _cluster_figure(cl: Clusters, stages: list[str], path: Path) -> None:
    """PCA points coloured by cluster, shaped by stage, sized by how often the same text came back."""
    from matplotlib.lines import Line2D

    fig = _figure(8.5, 6.0)
    ax = fig.add_subplot()
    colours = _cycle(len(cl.clusters))
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
    _save(fig, path)


def _cycle(n: int) -> list[Any]:
    from matplotlib import colormaps

    cmap: Callable[[int], Any] = colormaps["tab10"]
    return [cmap(i % 10) for i in range(max(n, 1))]
