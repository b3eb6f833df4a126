"""The docs agree with the command lines: every option a tool's parser takes is named in the doc that
documents that tool, and every option the doc's command examples give to that tool exists."""

from __future__ import annotations

import argparse
import re
from collections.abc import Callable
from pathlib import Path

import pytest

from companion.alarm_cli import build_parser as alarm_parser
from companion.cli import build_parser as companion_parser
from companion.eval_cli import build_parser as eval_parser
from landfall_eval.cli import build_parser as bench_parser
from landfall_ground.cli import _parser as ground_parser
from landfall_link.lidar_bridge import build_parser as lidar_bridge_parser
from simbridge.cli import build_parser as simbridge_parser
from simbridge.render_cli import build_parser as render_parser

ROOT = Path(__file__).resolve().parent.parent

# a tool as its examples start (the first word of a command line), its parsers, the doc that documents it
TOOLS: list[tuple[str, list[Callable[[], argparse.ArgumentParser]], str]] = [
    ("simbridge", [simbridge_parser, render_parser], "docs/simbridge.md"),
    ("companion", [companion_parser], "docs/companion.md"),
    ("trigger_alarm.py", [alarm_parser], "docs/companion.md"),
    ("companion-eval", [eval_parser], "docs/companion.md"),
    ("companion-bench", [bench_parser], "docs/bench.md"),
    ("landfall-ground", [ground_parser], "docs/ground.md"),
    ("landfall-lidar-bridge", [lidar_bridge_parser], "docs/sensor-stream.md"),
]
FLAG = re.compile(r"(?<![\w-])(--[a-z][a-z0-9-]*)")


def options(parser: argparse.ArgumentParser) -> set[str]:
    """Every long option of ``parser`` and of its subcommands."""
    found: set[str] = set()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                found |= options(sub)
        found |= {o for o in action.option_strings if o.startswith("--")}
    return found


def example_flags(doc: str, tool: str) -> set[str]:
    """The options given to ``tool`` in ``doc``'s code blocks: on lines whose first word is the tool
    (``python`` and a path before it allowed), and the lines that continue them (a trailing
    backslash, or indented under them)."""
    flags: set[str] = set()
    for block in re.findall(r"```[a-z]*\n(.*?)```", doc, re.S):
        ours = False
        carry = False
        for line in block.splitlines():
            words = line.split()
            if carry or (ours and line.startswith((" ", "\t"))):
                pass
            else:
                start = [w for w in words[:3] if w not in ("python", "python3", "$")]
                ours = bool(start) and Path(start[0]).name == tool
            carry = line.rstrip().endswith("\\")
            if ours:
                flags |= set(FLAG.findall(line.split("#")[0]))
    return flags


@pytest.mark.parametrize(("tool", "parsers", "doc"), TOOLS, ids=[t[0] for t in TOOLS])
def test_every_option_is_documented_and_every_documented_option_exists(
    tool: str, parsers: list[Callable[[], argparse.ArgumentParser]], doc: str
) -> None:
    text = (ROOT / doc).read_text()
    known = set().union(*(options(make()) for make in parsers))
    undocumented = sorted(f for f in known - {"--help"} if not re.search(re.escape(f) + r"(?![\w-])", text))
    assert not undocumented, f"{doc} does not name {tool}'s {undocumented}"
    stale = sorted(example_flags(text, tool) - known)
    assert not stale, f"{doc}'s examples give {tool} options it does not take: {stale}"
    assert example_flags(text, tool), f"{doc} has no example of {tool}"  # the check read something


def test_the_example_reader_follows_continuations_and_skips_other_tools() -> None:
    doc = (
        "```sh\nsimbridge --a \\\n  --b\ncompanion --c\n    --d\npython tools/simbridge --e # --f\n```\n"
        "text --g\n```\nsimbridge render --h\n```\n"
    )
    assert example_flags(doc, "simbridge") == {"--a", "--b", "--e", "--h"}
    assert example_flags(doc, "companion") == {"--c", "--d"}
