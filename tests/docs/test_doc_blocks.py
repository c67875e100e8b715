"""Every code block of the documentation runs: YAML parses (a chain or robot file loads with framechain's own
loaders), Python runs, and shell commands run with their shown output compared.

How a block is checked is written in an HTML comment on the line before its fence, unseen on the rendered
page: ``<!-- check: KIND [in=INPUTS] [file=NAME] [set=FILE:KEY=VALUE] [cmd="COMMAND"] -->``.

- ``chain`` / ``robot``: YAML loaded as CHAIN.yaml / robot.yaml; a ``yaml`` block without a check only parses.
- ``run``: ``console`` blocks hold ``$ COMMAND`` lines, each followed by its output; ``sh`` blocks hold
  commands only (each must succeed); a ``text`` (or ``yaml``) block with ``cmd=`` is that command's output;
  ``python`` blocks run. ``in=`` names the inputs they run beside (tests/docs/conftest.py); the blocks of one page with
  the same inputs run in page order in one folder, as a reader follows them.
- ``file=NAME``: the block is also that file among the inputs: on its page from where it stands (a command's
  output once the command ran), on other pages from the start.
- ``set=FILE:KEY=VALUE``: for this block only, FILE's dotted KEY set to the YAML VALUE (a variant).
- ``illustrative (WHY)``: not run (a placeholder path, a command that needs what tests lack), and says why.

Shown output is compared line by line: a line ``...`` stands for any lines, and ``...`` inside a line for any
text; ``done in N s`` is the machine's time. Blocks in ``text`` without a check are drawings.
"""

from __future__ import annotations

import contextlib
import difflib
import io
import os
import re
import shlex
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
#: The pages checked: the manual, and the README and ARCHITECTURE.md at the top.
#: (docs/architecture.md is ARCHITECTURE.md, linked: one page.)
PAGES = sorted({p.resolve() for p in [*(ROOT / "docs").glob("*.md"), ROOT / "README.md", ROOT / "ARCHITECTURE.md"]})
LANGUAGES = {"yaml", "python", "console", "sh", "text"}
KINDS = {"chain", "robot", "yaml", "run", "illustrative"}
#: Illustrative blocks are the exception: a few, each with its reason.
MAX_ILLUSTRATIVE = 8

_FENCE = re.compile(r"^```(\S*)\s*$")
_CHECK = re.compile(r"^<!-- check: (\w+)(.*?) -->$")
_ENV = re.compile(r"^[A-Z][A-Z0-9_]*=")
_TIMING = re.compile(r"done in [0-9.]+ s")


@dataclass(frozen=True)
class Block:
    """One fenced block of a page and how it is checked."""

    page: str
    line: int
    lang: str
    text: str
    kind: str = ""
    options: dict[str, str] = field(default_factory=dict)
    sets: tuple[str, ...] = ()
    why: str = ""

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"


def _check(comment: str) -> tuple[str, dict[str, str], tuple[str, ...], str]:
    match = _CHECK.match(comment)
    assert match is not None, comment
    kind, rest = match.group(1), match.group(2).strip()
    if kind == "illustrative":
        return kind, {}, (), rest.strip("()").strip()
    options: dict[str, str] = {}
    sets: list[str] = []
    for token in shlex.split(rest):
        key, _, value = token.partition("=")
        if key == "set":
            sets.append(value)
        else:
            options[key] = value
    return kind, options, tuple(sets), ""


def read_blocks(page: Path) -> list[Block]:
    """The fenced blocks of ``page``, with the check written before each."""
    lines = page.read_text().splitlines()
    name = page.relative_to(ROOT).as_posix()
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        fence = _FENCE.match(lines[i])
        if fence is None:
            i += 1
            continue
        end = next(j for j in range(i + 1, len(lines)) if lines[j].startswith("```"))
        comment = lines[i - 1] if i > 0 and lines[i - 1].startswith("<!-- check:") else ""
        kind, options, sets, why = _check(comment) if comment else ("", {}, (), "")
        blocks.append(Block(name, i + 1, fence.group(1), "\n".join(lines[i + 1:end]) + "\n", kind, options, sets,
                            why))
        i = end + 1
    return blocks


ALL_BLOCKS = [block for page in PAGES for block in read_blocks(page)]


def _sequences() -> list[tuple[str, str]]:
    """(page, inputs) for every run of blocks that runs in one folder."""
    seen: dict[tuple[str, str], None] = {}
    for block in ALL_BLOCKS:
        if block.kind == "run":
            seen[(block.page, block.options.get("in", "empty"))] = None
    return list(seen)


# -- the rules every block follows ---------------------------------------------------------------------------
def test_every_block_says_what_it_is() -> None:
    for block in ALL_BLOCKS:
        assert block.lang in LANGUAGES, f"{block.where}: a fence without a known language ({block.lang!r})"
        assert not block.kind or block.kind in KINDS, f"{block.where}: unknown check {block.kind!r}"
        if block.lang in ("console", "sh"):
            assert block.kind in ("run", "illustrative"), f"{block.where}: a shell block is run or illustrative"
        if block.lang == "python":
            assert block.kind in ("run", "illustrative"), f"{block.where}: a Python block is run or illustrative"
        if block.kind == "illustrative":
            assert block.why, f"{block.where}: an illustrative block says why it is not run"
        if block.lang == "text" and block.kind:
            assert block.kind == "illustrative" or "cmd" in block.options, block.where
    illustrative = [b.where for b in ALL_BLOCKS if b.kind == "illustrative"]
    assert len(illustrative) <= MAX_ILLUSTRATIVE, illustrative


@pytest.mark.parametrize("block", [b for b in ALL_BLOCKS if b.lang == "yaml"], ids=lambda b: b.where)
def test_yaml_blocks_parse_and_load(block: Block, tmp_path: Path, doc_inputs: Callable[[str, Path], None]) -> None:
    from framechain.config.chain import ChainConfig
    from framechain.config.robot import RobotConfig

    raw = yaml.safe_load(block.text)
    if block.kind in ("chain", "robot"):
        doc_inputs(block.options.get("in", "empty"), tmp_path)  # the files it names
    if block.kind == "chain":
        ChainConfig.from_dict(raw, where=block.where, base_dir=tmp_path)
    elif block.kind == "robot":
        RobotConfig.from_mapping(raw, base_dir=tmp_path, source=block.where)
    else:
        assert block.kind in ("", "yaml", "run", "illustrative"), block.where  # a run: its output is YAML


# -- running the blocks --------------------------------------------------------------------------------------
@contextlib.contextmanager
def _environment(cwd: Path, env: dict[str, str]) -> Iterator[None]:
    before = Path.cwd()
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    os.chdir(cwd)
    try:
        yield
    finally:
        os.chdir(before)
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


#: Plain progress lines come only after this long: never in the compared output.
_QUIET = {"FRAMECHAIN_PROGRESS_INTERVAL_S": "1000000"}


def run_command(line: str, cwd: Path) -> tuple[int, str]:
    """Run one shell line of the docs (``[VAR=value ...] framechain ARGS [> FILE]``) in ``cwd``: its exit code,
    and what it printed (stdout, then stderr)."""
    from framechain.cli.main import main

    tokens = shlex.split(line, comments=True)
    env = dict(_QUIET)
    while tokens and _ENV.match(tokens[0]):
        key, _, value = tokens.pop(0).partition("=")
        env[key] = value
    redirect = None
    if len(tokens) > 2 and tokens[-2] == ">":
        redirect, tokens = tokens[-1], tokens[:-2]
    assert tokens, line
    assert tokens[0] == "framechain", f"only framechain runs here: {line!r}"
    out, err = io.StringIO(), io.StringIO()
    with _environment(cwd, env), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(tokens[1:])
        except SystemExit as stop:
            code = int(stop.code or 0)
    if redirect is not None:
        (cwd / redirect).write_text(out.getvalue())
        return code, err.getvalue()
    return code, out.getvalue() + err.getvalue()


def _normalised(text: str) -> str:
    lines = [_TIMING.sub("done in T s", line.rstrip()) for line in text.splitlines()]
    while lines and not lines[-1]:
        lines.pop()
    return "".join(line + "\n" for line in lines)


def output_pattern(shown: str) -> re.Pattern[str]:
    """``shown`` as a pattern: a line ``...`` is any lines, ``...`` in a line any text."""
    regex = ""
    for line in _normalised(shown).splitlines():
        if line == "...":
            regex += r"(?:[^\n]*\n)*?"
        else:
            regex += r"[^\n]*?".join(re.escape(part) for part in line.split("...")) + r"\n"
    return re.compile(regex)


def assert_shown(shown: str, actual: str, where: str) -> None:
    if output_pattern(shown).fullmatch(_normalised(actual)):
        return
    diff = "\n".join(difflib.unified_diff(_normalised(shown).splitlines(), _normalised(actual).splitlines(),
                                          "shown", "actual", lineterm=""))
    pytest.fail(f"{where}: the output shown is not what the command prints\n{diff}")


def _console(text: str) -> list[tuple[str, str]]:
    """``$ command`` lines of a console block, each with the output shown under it."""
    runs: list[tuple[str, str]] = []
    for line in text.splitlines():
        if line.startswith("$ "):
            runs.append((line[2:], ""))
        else:
            assert runs, f"output before any command: {line!r}"
            runs[-1] = (runs[-1][0], runs[-1][1] + line + "\n")
    return runs


def _set_key(document: Any, path: str, value: Any) -> None:
    keys = path.split(".")
    node = document
    for key in keys[:-1]:
        node = node[int(key)] if isinstance(node, list) else node.setdefault(key, {})
    last = keys[-1]
    if isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value


@contextlib.contextmanager
def _variant(folder: Path, sets: tuple[str, ...]) -> Iterator[None]:
    """Each ``FILE:KEY=VALUE`` of ``sets`` applied to FILE in ``folder`` for the block's run only."""
    saved: dict[Path, str] = {}
    for item in sets:
        name, _, assignment = item.partition(":")
        key, _, value = assignment.partition("=")
        path = folder / name
        saved.setdefault(path, path.read_text())
        document = yaml.safe_load(path.read_text())
        _set_key(document, key, yaml.safe_load(value))
        path.write_text(yaml.safe_dump(document, sort_keys=False))
    try:
        yield
    finally:
        for path, text in saved.items():
            path.write_text(text)


def run_block(block: Block, folder: Path) -> None:
    """Run ``block`` in ``folder`` and compare what it shows with what it prints."""
    with _variant(folder, block.sets):
        if block.lang == "python":
            with _environment(folder, {}):
                exec(compile(block.text, block.where, "exec"), {"__name__": "__docs__"})
        elif block.lang == "sh":
            for line in block.text.splitlines():
                if line.strip() and not line.lstrip().startswith("#"):
                    code, printed = run_command(line, folder)
                    assert code == 0, f"{block.where}: `{line}` exited {code}:\n{printed}"
        elif "cmd" in block.options:
            code, printed = run_command(block.options["cmd"], folder)
            assert code in (0, 1), f"{block.where}: exit {code}"
            assert_shown(block.text, printed, block.where)
        else:
            for command, shown in _console(block.text):
                code, printed = run_command(command, folder)
                assert code in (0, 1), f"{block.where}: `{command}` exited {code}:\n{printed}"
                assert_shown(shown, printed, f"{block.where} `{command}`")


def _write_files(blocks: list[Block], folder: Path) -> None:
    for block in blocks:
        (folder / block.options["file"]).write_text(block.text)


@pytest.mark.parametrize(("page", "inputs"), _sequences(), ids=str)
def test_the_blocks_run_and_print_what_they_show(page: str, inputs: str, tmp_path: Path,
                                                  doc_inputs: Callable[[str, Path], None]) -> None:
    doc_inputs(inputs, tmp_path)
    files = [b for b in ALL_BLOCKS if "file" in b.options and b.options.get("in", "empty") in inputs.split("+")]
    _write_files([b for b in files if b.page != page], tmp_path)
    for block in ALL_BLOCKS:
        if block.page != page or block.options.get("in", "empty") != inputs:
            continue
        if block.kind == "run":
            run_block(block, tmp_path)
        if "file" in block.options:  # after its run: a command's output kept as a file
            _write_files([block], tmp_path)


def test_the_output_comparison_honours_elisions() -> None:
    shown = "first\n...\nmiddle ... end\nlast\n"
    assert output_pattern(shown).fullmatch("first\nany\nlines\nmiddle of the end\nlast\n")
    assert output_pattern(shown).fullmatch("first\nmiddle  end\nlast\n")
    assert not output_pattern(shown).fullmatch("first\nmiddle end\nlast\nmore\n")
    assert not output_pattern("a\nb\n").fullmatch("a\nx\nb\n")
    assert output_pattern("done in 3.7 s\n").fullmatch(_normalised("done in 12.25 s\n"))
