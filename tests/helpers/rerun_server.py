"""A Rerun viewer's gRPC server for the tests that stream to one: the rerun executable serving on a free local port
and saving what it receives to a file the tests read back."""

from __future__ import annotations

import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest


def rerun_executable() -> str | None:
    """The rerun executable beside this Python, or on PATH."""
    return shutil.which("rerun") or shutil.which("rerun", path=str(Path(sys.executable).parent))


@dataclass(frozen=True)
class GrpcServer:
    url: str
    rrd: Path
    process: subprocess.Popen[bytes]


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


@contextmanager
def serving_grpc(tmp_path: Path) -> Iterator[GrpcServer]:
    """The rerun executable serving gRPC on a free port and saving what it receives; skips the test without it."""
    exe = rerun_executable()
    if exe is None:
        pytest.skip("the rerun executable is not installed")
    port = free_port()
    rrd = tmp_path / "received.rrd"
    process = subprocess.Popen([exe, "--serve-grpc", "--port", str(port), "--save", str(rrd)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            with socket.socket() as sock:
                if sock.connect_ex(("127.0.0.1", port)) == 0:
                    break
            time.sleep(0.1)
        else:
            pytest.fail("the Rerun gRPC server did not start")
        yield GrpcServer(f"rerun+http://127.0.0.1:{port}/proxy", rrd, process)
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def received_entities(server: GrpcServer) -> set[str]:
    """The entities the server has saved, once its file holds the run's summary (or after 10 s)."""
    from rerun.chunk import RrdReader

    deadline = time.monotonic() + 10
    entities: set[str] = set()
    while time.monotonic() < deadline:
        if server.rrd.is_file() and server.rrd.stat().st_size:
            try:
                entities = {c.entity_path for c in RrdReader(server.rrd).stream()}
            except RuntimeError:  # the server is still writing the last message
                entities = set()
            if "/summary" in entities:
                break
        time.sleep(0.2)
    return entities
