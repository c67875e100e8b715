"""A long run says how far it is: plain lines on stderr when it is not a terminal (a CI log), with counts and time
left, at most every few seconds; nothing with -q. Run as a user runs it: a subprocess whose stderr is a pipe."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader

from framechain.catalogue import Fault
from framechain.cli.common import PROGRESS_INTERVAL_S
from framechain.sim.logs import write_scene
from framechain.sim.scene import InjectedFault, SceneSpec, generate

BOOTSTRAP = 6
LINE = re.compile(r"^framechain: (?P<stage>.+?)(?: (?P<pct>\d+)% \((?P<done>[\d,]+) of (?P<total>[\d,]+) "
                  r"(?P<unit>\w+)\)(?:, (?P<left>.+) left)?)?$")


@pytest.fixture(scope="module")
def episode(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("progress")
    scene = generate(SceneSpec(seed=5, duration_s=30.0, width=320, height=240, focal_px=300.0, evidence="hops",
                               faults=(InjectedFault(Fault.LATENCY, "robot", {"offset_s": -0.03}),)))
    log = write_scene(scene, root / "episode.mcap")
    chain = root / "chain.yaml"
    chain.write_text(yaml.safe_dump(scene.chain.to_dict()))
    return log, chain


def _attribute(log: Path, chain: Path, out: Path, *extra: str, interval_s: float | None = None,
               ) -> tuple[subprocess.CompletedProcess[str], float]:
    env = dict(os.environ)
    env.pop("FRAMECHAIN_PROGRESS_INTERVAL_S", None)
    if interval_s is not None:
        env["FRAMECHAIN_PROGRESS_INTERVAL_S"] = str(interval_s)
    start = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "framechain", "attribute", str(log), "--chain", str(chain), "--out",
                           str(out), "--bootstrap", str(BOOTSTRAP), "--format", "json", *extra],
                          capture_output=True, text=True, env=env, timeout=600, check=False)
    return done, time.monotonic() - start


def test_piped_progress_counts_what_it_reads_and_resamples(episode: tuple[Path, Path], tmp_path: Path) -> None:
    log, chain = episode
    done, _ = _attribute(log, chain, tmp_path / "o", interval_s=0)  # every report a line
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()
    parsed = [LINE.match(line) for line in lines]
    assert all(parsed), [line for line, m in zip(lines, parsed, strict=True) if not m]
    reading = [m for m in parsed if m and m["stage"] == f"reading {log.name}"]
    counts = [int(m["done"].replace(",", "")) for m in reading]
    totals = {int(m["total"].replace(",", "")) for m in reading}
    with log.open("rb") as f:
        stats = make_reader(f).get_summary().statistics  # type: ignore[union-attr]
    (total,) = totals
    assert 4096 < total <= stats.message_count  # type: ignore[union-attr]  # the messages of the chain's topics
    assert counts == sorted(counts)
    assert (counts[0], counts[-1]) == (0, total)
    assert len(counts) > 2
    assert reading[-1]["pct"] == "100"
    assert all(m["unit"] == "messages" for m in reading)
    assert any(m["left"] for m in reading[1:-1])  # time left while it reads
    boot = [m for m in parsed if m and m["stage"].startswith("bootstrapping ")]
    assert [int(m["done"]) for m in boot][-1] == BOOTSTRAP
    assert {m["total"] for m in boot} == {str(BOOTSTRAP)}
    assert {m["unit"] for m in boot} == {"resamples"}
    assert any(m and m["stage"].startswith("fitting ") and m["unit"] == "models" for m in parsed)
    assert any(m and m["stage"].startswith("replaying ") for m in parsed)
    assert "writing the outputs" in {m["stage"] for m in parsed if m}
    assert "latency" in done.stdout  # the result is still on stdout, untouched by progress


def test_piped_progress_is_a_line_every_few_seconds_and_quiet_silences_it(episode: tuple[Path, Path],
                                                                         tmp_path: Path) -> None:
    log, chain = episode
    done, elapsed_s = _attribute(log, chain, tmp_path / "o")
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stderr.splitlines() if line.startswith("framechain: ")]
    assert len(lines) <= elapsed_s / PROGRESS_INTERVAL_S  # the first one interval into the run, then one per interval
    assert all(LINE.match(line) for line in lines)
    quiet, _ = _attribute(log, chain, tmp_path / "q", "-q", interval_s=0)
    assert quiet.returncode == 0
    assert quiet.stderr == ""
