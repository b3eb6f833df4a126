"""The report's HTML: the page, tables, number formats and names."""

from __future__ import annotations

import datetime as dt
import html
import json
import re
from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    pass

from landfall_eval.report.episodes import as_number

NA = "\N{EN DASH}"  # a missing figure in a table


PAGE = """<!doctype html>
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


def escape(x: object) -> str:
    return html.escape(str(x), quote=True)


def table(head: Sequence[str], rows: Iterable[Sequence[object]]) -> str:
    """An HTML table; cells are escaped, numbers (already formatted as text or not) right-aligned."""
    out = ["<table><tr>", *(f"<th>{escape(h)}</th>" for h in head), "</tr>"]
    for row in rows:
        cells = (
            f'<td class="n">{escape(c)}</td>'
            if isinstance(c, int | float) or NUMERIC.match(str(c))
            else f"<td>{escape(c)}</td>"
            for c in row
        )
        out += ["<tr>", *cells, "</tr>"]
    out.append("</table>")
    return "".join(out)


NUMERIC = re.compile(r"^[-+]?[\d.,]+( ?(%|s|m|MB|x))?$")


def fmt(x: float | None, digits: int = 2, unit: str = "") -> str:
    return NA if x is None else f"{x:.{digits}f}{unit}"


def pct(x: float | None) -> str:
    return NA if x is None else f"{100 * x:.1f} %"


def median_of(xs: Iterable[float | None]) -> float | None:
    v = [x for x in xs if x is not None]
    return float(np.median(v)) if v else None


def mean_of(xs: Iterable[float | None]) -> float | None:
    v = [x for x in xs if x is not None]
    return float(np.mean(v)) if v else None


def img_tag(name: str, alt: str) -> str:
    return f'<p><img src="figures/{escape(name)}" alt="{escape(alt)}"></p>'


def header(results: Mapping[str, Any], config: Mapping[str, Any]) -> str:
    created = as_number(results.get("created_unix_s"))
    when = (
        NA
        if created is None
        else dt.datetime.fromtimestamp(created, dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    )
    out = [
        f"<h1>companion-bench report: {escape(results.get('command', 'results'))}</h1>",
        f"<p>created {escape(when)}, schema {escape(results.get('schema', NA))}</p>",
    ]
    if config:
        rows = [(k, v if isinstance(v, str) else json.dumps(v)) for k, v in config.items()]
        out += ["<h2>Configuration</h2>", table(("setting", "value"), rows)]
    return "\n".join(out)


def short(text: str, limit: int = 240) -> str:
    return text if len(text) <= limit else text[: limit - 1] + "…"


def slug(s: str) -> str:
    return re.sub(r"[^A-Za-z0-9_-]+", "_", s).strip("_") or "scenario"


def unique_name(name: str, used: set[str]) -> str:
    stem, k = name.removesuffix(".png"), 1
    while name in used:
        k += 1
        name = f"{stem}_{k}.png"
    used.add(name)
    return name
