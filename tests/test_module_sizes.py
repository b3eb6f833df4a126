"""The house rule on module size: a module of the product over 600 lines says in its docstring why it
is one idea ("over 600 lines" and the reason), so that a long file is a decision, not drift."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("companion", "landfall_link", "simbridge", "landfall_eval", "landfall_train", "landfall_ground")
MAX_LINES = 600


def long_modules_without_a_reason(root: Path = ROOT) -> list[str]:
    """The modules of ``PACKAGES`` under ``root`` longer than ``MAX_LINES`` whose docstring does not say
    it is over 600 lines (and so why)."""
    out = []
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            text = path.read_text(encoding="utf-8")
            lines = text.count("\n")
            if lines <= MAX_LINES:
                continue
            doc = ast.get_docstring(ast.parse(text)) or ""
            if f"over {MAX_LINES} lines" not in " ".join(doc.split()):
                out.append(f"{path.relative_to(root)} ({lines} lines)")
    return out


def test_every_long_module_says_why_it_is_one_idea() -> None:
    assert long_modules_without_a_reason() == []


def test_the_rule_catches_a_long_module_without_a_reason(tmp_path: Path) -> None:
    (tmp_path / "companion").mkdir()
    (tmp_path / "companion" / "long.py").write_text('"""A module."""\n' + "x = 1\n" * 601)
    (tmp_path / "companion" / "kept.py").write_text(
        '"""A module (one module over 600\n lines: one state machine)."""\n' + "x = 1\n" * 601
    )
    (tmp_path / "companion" / "short.py").write_text('"""A module."""\n' + "x = 1\n" * 10)
    assert long_modules_without_a_reason(tmp_path) == ["companion/long.py (602 lines)"]
