"""What ``framechain info`` says a log still needs, read from its JSON."""

from __future__ import annotations

import json

import pytest

from framechain.cli.main import main


def info_needs(capsys: pytest.CaptureFixture[str], *args: str) -> dict[str, dict[str, str]]:
    """``info ARGS --json``'s needs, by piece (mount, intrinsics, depth, ...); the command must exit 0."""
    assert main(["info", *args, "--json", "-q"]) == 0
    return {n["piece"]: n for n in json.loads(capsys.readouterr().out)["needs"]}
