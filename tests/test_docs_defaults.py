"""One default per option: every key of the companion's configuration schema has the same default in
the schema (companion/config_schema.py), in deploy/companion.toml (its value and its "Default ..."
comment) and wherever README.md or docs/ state it (a key named with its default beside it, and the
prose that gives the defaults without naming the keys)."""

from __future__ import annotations

import enum
import re
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest
from pydantic import BaseModel, SecretStr

from companion.config_schema import DEFAULTS, CompanionConfig
from tests.test_deploy import _stated_defaults

ROOT = Path(__file__).resolve().parent.parent
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
UNSET: tuple[object, ...] = (None, "", [], {})  # what the file writes as "" or [] the schema may hold as None


def schema_keys(model: type[BaseModel] = CompanionConfig, prefix: str = "") -> Iterator[str]:
    """Every option as a dotted key (``recovery.search_window_s.high``); a table of profiles is one."""
    for name, field in model.model_fields.items():
        kind = field.annotation
        if isinstance(kind, type) and issubclass(kind, BaseModel):
            yield from schema_keys(kind, f"{prefix}{name}.")
        else:
            yield prefix + name


def plain(value: object) -> object:
    """A default as TOML would write it: enums as their values, tuples as lists, paths as text."""
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, tuple | list):
        return [plain(v) for v in value]
    if isinstance(value, Path | SecretStr):
        return str(value)
    return value


def default_of(key: str) -> object:
    owner: object = DEFAULTS
    for part in key.split("."):
        owner = getattr(owner, part)
    return plain(owner)


def same(stated: object, default: object) -> bool:
    if stated in UNSET or default in UNSET:
        return stated in UNSET and default in UNSET
    return bool(stated == default)


def file_value(values: dict[str, object], key: str) -> tuple[bool, object]:
    """``key``'s value in the parsed deploy/companion.toml, and whether the file sets it at all."""
    node: object = values
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            return False, None
        node = node[part]
    return True, node


# What the docs write after a key's name to state its default. VALUE: a backticked literal, a range
# "1800-2200" (a [low, high] pair), a HOST:PORT, a number (its unit after it), or on/off; BARE: the same
# but a backticked literal (after a bare parenthesis or comma, that is more often another key).
_PLAIN = r"\d+(?:\.\d+)?-\d+(?:\.\d+)?|\d{1,3}(?:\.\d{1,3}){3}:\d+|-?\d+(?:\.\d+)?|on|off"
_VALUE = r"(?P<v>`[^`]+`|" + _PLAIN + ")"
_BARE = r"(?P<v>" + _PLAIN + ")"
STATEMENTS = [
    re.compile(r"^\s*\(default\s+" + _VALUE),  # `k` (default 10 m
    re.compile(r"^\s*\(" + _BARE + r"(?=[\s),;:])"),  # `k` (10 s)
    re.compile(r"^,\s*default\s+" + _VALUE),  # `k`, default 100 ms
    re.compile(r"^,\s*" + _BARE + r"(?:\s+[A-Za-z%]+)?\s*[);]"),  # (`k`, 6 s)
    re.compile(r"^\s*\((?P<v>on|off|[a-z]+) by default\)"),  # `k` (hold by default)
    re.compile(r"^[^.;()`]{0,40}\(default\s+" + _VALUE),  # `k` of the site (default 10 m
    re.compile(r"^[^.;`]{0,25}\**" + _VALUE + r"\**,?\s*\(?the default\b"),  # `k`: `hold` (the default
    re.compile(r"^\s*=\s*" + _BARE + r"(?=[\s),;:])"),  # (`k` = 4: ...)
]


def stated_value(text: str) -> object:
    """A value as a doc writes it, as the schema would hold it."""
    text = text.strip("`")
    if text == "none":
        return None
    if re.fullmatch(r"\d+(?:\.\d+)?-\d+(?:\.\d+)?", text):
        return [float(n) for n in text.split("-")]
    if text in ("on", "off"):
        return text == "on"
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def doc_statements(text: str, keys: list[str]) -> Iterator[tuple[str, str, int]]:
    """(key, the value as written, line) for each default ``text`` states beside a key's name: the dotted
    key in backticks, or ``key = value`` in backticks followed by "the default", or a key's last part
    alone where no other key ends in it and it has an underscore (``hedge_after_s``, not ``high``)."""
    leaves = [k.rsplit(".", 1)[1] for k in keys]
    names = {k: k for k in keys} | {
        leaf: key for leaf, key in zip(leaves, keys, strict=True) if "_" in leaf and leaves.count(leaf) == 1
    }
    flat = re.sub(r"\s+", " ", text)  # a statement may run across lines
    offsets = _flat_offsets(text)

    def line(pos: int) -> int:
        return text.count("\n", 0, offsets[pos]) + 1

    pattern = re.compile(r"`(" + "|".join(re.escape(n) for n in sorted(names, key=len, reverse=True)) + r")`")
    for m in pattern.finditer(flat):
        rest = flat[m.end() : m.end() + 120]
        found = next((f for f in (s.search(rest) for s in STATEMENTS) if f is not None), None)
        if found is not None:
            yield names[m[1]], found["v"], line(m.start())
    assignment = re.compile(r"`(" + "|".join(map(re.escape, keys)) + r") = ([^`]+)`\**,?\s*\(?the default\b")
    for m in assignment.finditer(flat):
        yield m[1], m[2], line(m.start())


def _flat_offsets(text: str) -> list[int]:
    """For each character of ``re.sub(r"\\s+", " ", text)``, its offset in ``text``."""
    out: list[int] = []
    for m in re.finditer(r"\s+|\S+", text):
        out.extend([m.start()] if m[0].isspace() else range(m.start(), m.end()))
    return out


def prose(d: CompanionConfig) -> list[tuple[str, str]]:
    """Prose that gives defaults without naming the keys: (doc, the words as the defaults ``d`` make them)."""
    r, rounds, window, p, m = (
        d.recovery,
        d.recovery.rounds_by_criticality,
        d.recovery.search_window_s,
        d.perception,
        d.mqtt,
    )
    halved = {0.5: "halved"}.get(
        d.reasoner.critical_deadline_factor, f"x {d.reasoner.critical_deadline_factor}"
    )
    return [
        ("docs/companion.md", f"(the default, `{d.mavlink.url}`)"),
        ("docs/companion.md", f"`{d.reasoner.name}` (the default: no network"),
        (
            "docs/companion.md",
            f"(rank {d.reasoner.rank_deadline_s:g} s, confirm {d.reasoner.confirm_deadline_s:g} s, "
            f"{halved} for a critical alarm)",
        ),
        ("docs/companion.md", f"low {rounds.low}, high {rounds.high}, critical {rounds.critical} by default"),
        (
            "docs/companion.md",
            f"a {r.search_reserve_pct:g} % reserve and the alarm's window lasts (critical "
            f"{window.critical:g} s, high {window.high:g} s, low {window.low:g} s of the autopilot's clock)",
        ),
        ("docs/companion.md", f"fits planes in {p.window_cells} x {p.window_cells}-cell windows"),
        (
            "docs/companion.md",
            f"proposes up to {p.max_candidates} flat surfaces of at least {p.min_area_m2:g} m2 whose "
            f"landable part ({p.edge_margin_m:g} m clear of every edge)",
        ),
        (
            "docs/companion.md",
            f"descends by {r.descent_fraction * 100:g} % of its height above the site and, at "
            f"{r.final_land_m:g} m or less, the autopilot's land mode finishes",
        ),
        (
            "docs/companion.md",
            f"(within {r.arrival_tolerance_m:g} m and slower than {r.arrival_speed_m_s:g} m/s)",
        ),
        ("docs/companion.md", f"(default `{m.topic_prefix}/{m.vehicle_id}/`)"),
        ("docs/companion.md", f"{m.thumbnail_width_px}-pixel JPEG thumbnail"),
        ("docs/companion.md", f"`telemetry` ({m.telemetry_hz:g} Hz)"),
        ("docs/recovery.md", f"(low {window.low:g}, high {window.high:g}, critical {window.critical:g})"),
        ("docs/hardware.md", f"(`--mavlink {d.mavlink.url}`, the default)"),
        ("docs/hardware.md", f"a battery under {d.alarms.battery_critical_pct:g} %"),
    ]


def test_doc_statement_reader_finds_each_way_of_stating_a_default() -> None:
    keys = ["a.wait_s", "a.mode", "b.size_m", "b.band_us", "b.on", "b.endpoint", "c.high"]
    text = (
        "`a.wait_s` (10 s) and\n`a.mode`: `hold` (the default: ...); `b.size_m` of it (default 2 m); "
        "`b.band_us` (default 1800-2200 us); (`wait_s`, 3 s); `b.on` (off by default); `c.high` (7); "
        '`b.endpoint`, 127.0.0.1:5601 TCP; `a.mode = "land"`, the default; `high` (8); '
        "`a.wait_s` 4 (a test's setting); "
        "`b.size_m` is 2 m, the rest of a long sentence that says `x` (the default); `size_m` = 5: more"
    )
    found = [(k, stated_value(v), n) for k, v, n in doc_statements(text, keys)]
    assert found == [
        ("a.wait_s", 10.0, 1), ("a.mode", "hold", 2), ("b.size_m", 2.0, 2),
        ("b.band_us", [1800.0, 2200.0], 2), ("a.wait_s", 3.0, 2), ("b.on", False, 2), ("c.high", 7.0, 2),
        ("b.endpoint", "127.0.0.1:5601", 2), ("b.size_m", 5.0, 2), ("a.mode", "land", 2),
    ]  # fmt: skip


def test_each_default_is_the_same_in_the_schema_the_example_file_and_the_docs() -> None:
    keys = list(schema_keys())
    values = tomllib.loads((ROOT / "deploy" / "companion.toml").read_text())
    wrong, unset = [], []
    for key in keys:
        present, value = file_value(values, key)
        if not present:
            unset.append(key)
        elif not same(value, default_of(key)):
            wrong.append(
                f"deploy/companion.toml: {key} = {value!r}, the schema's default {default_of(key)!r}"
            )
    assert unset == ["mavlink.signing_key", "reasoner.profiles"]  # shown commented out: a secret, examples
    stated = {f"{section}.{key}": (text, n) for section, key, text, n in _stated_defaults()}
    for key, (text, n) in stated.items():
        if key in keys and not same(stated_value(text), default_of(key)):
            wrong.append(
                f"deploy/companion.toml:{n}: {key}: 'Default {text}', the schema's {default_of(key)!r}"
            )
    in_docs = 0
    for doc in DOCS:
        for key, text, n in doc_statements(doc.read_text(), keys):
            in_docs += 1
            if not same(stated_value(text), default_of(key)):
                name = doc.relative_to(ROOT)
                wrong.append(f"{name}:{n}: {key} {text}, the schema's default is {default_of(key)!r}")
    assert in_docs >= 25, in_docs  # the reader found the docs' statements
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize(("doc", "words"), prose(DEFAULTS))
def test_the_docs_prose_gives_the_schemas_defaults(doc: str, words: str) -> None:
    text = re.sub(r"\s+", " ", (ROOT / doc).read_text())
    assert words in text, f"{doc} does not say {words!r} (the schema's defaults)"


def test_the_prose_check_follows_the_defaults() -> None:
    changed = CompanionConfig.model_validate({"recovery": {"rounds_by_criticality": {"high": 5}}})
    differs = [
        words for (_, words), (_, old) in zip(prose(changed), prose(DEFAULTS), strict=True) if words != old
    ]
    assert differs == ["low 10, high 5, critical 3 by default"]
