"""Every pointer to the docs resolves: a message or docstring of framechain/ that says "see docs/PAGE.md#anchor",
and every link of the README and ARCHITECTURE.md, names a page that exists and a heading on it. The README is
the front door: under 250 lines, with the two commands a fresh machine needs, the test command CI runs."""

from __future__ import annotations

import argparse
import re
import shlex
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import markdown
import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
#: A pointer in framechain's text: docs/PAGE.md, optionally with #anchor.
_POINTER = re.compile(r"docs/([\w-]+\.md)(?:#([\w-]+))?")
#: A relative Markdown link: [text](target).
_LINK = re.compile(r"\]\(([^)\s]+)\)")


def _ids(tokens: list[dict[str, Any]]) -> Iterator[str]:
    for token in tokens:
        yield token["id"]
        yield from _ids(token["children"])


def heading_anchors(page: Path) -> set[str]:
    """The anchors of ``page``'s headings, made as mkdocs makes them (Python-Markdown's toc extension)."""
    md = markdown.Markdown(extensions=["toc", "tables", "fenced_code"])
    md.convert(page.read_text())
    return set(_ids(md.toc_tokens))  # type: ignore[attr-defined]


def _pointers() -> list[tuple[str, str, str]]:
    found = []
    for source in sorted((ROOT / "framechain").rglob("*.py")):
        for match in _POINTER.finditer(source.read_text()):
            found.append((source.relative_to(ROOT).as_posix(), match.group(1), match.group(2) or ""))
    return found


def test_framechain_points_at_the_docs_not_the_readme() -> None:
    assert _pointers(), "no message points to a docs page"
    for source in sorted((ROOT / "framechain").rglob("*.py")):
        assert "README" not in source.read_text(), f"{source}: point to a docs page (docs/PAGE.md#heading)"


@pytest.mark.parametrize(("source", "page", "anchor"), _pointers(), ids=str)
def test_every_docs_pointer_in_framechain_resolves(source: str, page: str, anchor: str) -> None:
    assert (DOCS / page).is_file(), f"{source}: docs/{page} does not exist"
    if anchor:
        assert anchor in heading_anchors(DOCS / page), f"{source}: docs/{page} has no heading #{anchor}"


@pytest.mark.parametrize("page", ["README.md", "ARCHITECTURE.md"])
def test_links_of_the_top_pages_resolve(page: str) -> None:
    for target in _LINK.findall((ROOT / page).read_text()):
        if "://" in target:
            continue
        path, _, anchor = target.partition("#")
        resolved = ROOT / path if path else ROOT / page
        assert resolved.exists(), f"{page}: {target} does not exist"
        if anchor:
            assert anchor in heading_anchors(resolved), f"{page}: {path} has no heading #{anchor}"


def _fenced(text: str, language: str) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```", text, flags=re.MULTILINE | re.DOTALL)


def test_the_readme_is_a_front_door() -> None:
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) < 250
    (quick_start,) = _fenced(readme, "sh")
    commands = [line.split("#")[0].strip() for line in quick_start.splitlines()]
    assert commands == ["make demo", "make test"]
    # CI runs the test command the README gives.
    ci = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()]
    assert "make test" in ci
    # The demo output shown is the output of what `make demo` runs.
    makefile = (ROOT / "Makefile").read_text()
    recipe = makefile[makefile.index("\ndemo:"):].splitlines()[2].strip()
    shown = re.search(r'<!-- check: run cmd="([^"]+)" -->\n```text', readme)
    assert shown is not None
    assert shlex.split(recipe)[1:] == shlex.split(shown.group(1))[1:]
    # One line per command, each linked to its section of the manual.
    table = [line for line in readme.splitlines() if line.startswith("| [`framechain ")]
    assert len(table) == 9


def test_the_batch_section_names_the_fleet_table_columns() -> None:
    from framechain.fleet import FLEET_SCHEMA

    page = (DOCS / "cli.md").read_text()
    section = page[page.index("## batch"):page.index("## demo")]
    named = re.findall(r"`([a-z_]+)`", section.split("fleet.parquet", 1)[1].split(";", 1)[0])
    assert named, "the batch section lists the fleet table's columns"
    assert set(named) <= set(FLEET_SCHEMA.names), set(named) - set(FLEET_SCHEMA.names)
    assert {"log", "chain"} <= set(named)


def _commands(parser: argparse.ArgumentParser, prefix: str = "") -> Iterator[tuple[str, argparse.ArgumentParser]]:
    """Every command of the CLI with its parser, nested ones as ``lab tilt``."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, command in action.choices.items():
                full = f"{prefix}{name}"
                nested = any(isinstance(a, argparse._SubParsersAction) for a in command._actions)
                yield from _commands(command, f"{full} ") if nested else [(full, command)]


def test_the_commands_page_names_every_option_of_every_command() -> None:
    """docs/cli.md is the manual: each command's section (or the options every command takes, above them)
    names each of its long options."""
    from framechain.cli.main import build_parser

    page = (DOCS / "cli.md").read_text()
    shared = page[: page.index("\n## ")]
    missing: dict[str, list[str]] = {}
    commands = dict(_commands(build_parser()))
    assert {"info", "tf", "replay", "attribute", "report", "export", "batch", "demo", "lab tilt"} <= set(commands)
    for name, command in commands.items():
        start = page.index(f"\n## {name}\n")
        section = page[start: page.find("\n## ", start + 1)]
        options = {o for a in command._actions for o in a.option_strings if o.startswith("--") and o != "--help"}
        # Whole options only: --episodes does not document --episode.
        absent = sorted(o for o in options if not re.search(re.escape(o) + r"(?![\w-])", section + shared))
        if absent:
            missing[name] = absent
    assert not missing, missing
