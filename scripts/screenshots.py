"""Screenshots of the real Rerun viewer on framechain recordings (slow: not part of the tests).

How: ``rerun REC.rrd VIEW.rbl --serve-web`` hosts the web viewer and serves the recording over
gRPC; headless Chromium renders it with SwiftShader (WebGL on the CPU; no GPU, no display). The
script drives Chromium over the DevTools protocol: it takes a screenshot every 5 s until the viewer
shows data, waits ``--settle`` seconds more (JPEGs are decoded asynchronously: earlier shots show a
spinner where the image goes) and keeps the last one. The blueprint ``VIEW.rbl`` is framechain's
default for what the recording holds (its views with data, its cameras, its timelines) with the side
panels collapsed. The viewer opens at the end of the timeline: the shot shows the last observation.

Tried first: ``chromium --screenshot --virtual-time-budget=N`` works on an idle machine, but under
load the budget ran out while the viewer was still loading (a dark page, or no recording yet). A
native viewer under Xvfb with llvmpipe gave all-black captures on this machine. Measured on a busy
2-core machine: about 1 minute per screenshot.

    .venv/bin/python scripts/screenshots.py --demo docs/images/demo_viewer.png
    .venv/bin/python scripts/screenshots.py --rrd aruco.rrd --out docs/images/aruco_viewer.png
    .venv/bin/python scripts/screenshots.py --rrd quad.rrd --body rig --world rig --out quad.png
    .venv/bin/python scripts/screenshots.py --rrd episode.rrd --world world --out episode.png
    .venv/bin/python scripts/screenshots.py --rrd recording.rrd --blueprint recording.rbl --out recording.png

Needs ``chromium`` on PATH (Debian: ``apt-get install chromium``).
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
import urllib.parse
import urllib.request
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RERUN = ROOT / ".venv" / "bin" / "rerun"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def write_blueprint(path: Path, rrd: Path, *, body: str, world: str, curves_first: bool = False) -> None:
    """framechain's default blueprint of the recording (the views that have data in it) with the side panels
    collapsed, for application ``framechain``."""
    from framechain.config.chain import ChainFrames
    from framechain.sinks.rerun import default_blueprint

    logged, cameras, timelines = recorded_layout(rrd)
    camera = next((frame for frame, root, _ in cameras if root == "/camera"), cameras[0][0] if cameras else "camera")
    titles = [(entity, f"Error vs {entity.rsplit('/', 1)[-1]}") for entity in recorded_curves(rrd)]
    blueprint = default_blueprint(ChainFrames(camera=camera, body=body, world=world), logged, cameras=cameras,
                                  collapse_panels=True, curves=titles, curves_first=curves_first,
                                  window_s=recorded_window(rrd), timelines=timelines)
    blueprint.save("framechain", path)


Bounds = tuple[float, float, float, float]


def recorded_layout(rrd: Path) -> tuple[dict[str, int], list[tuple[str, str, Bounds | None]], list[str]]:
    """What the recording holds: rows per entity, its cameras (optical frame, entity, the view's bounds: the
    recording's own for the chain camera, the whole image for the others) and its timelines (the stamps' first)."""
    from rerun.chunk import RrdReader

    logged: dict[str, int] = {}
    cameras: dict[str, tuple[str, str, Bounds | None]] = {}
    names: set[str] = set()
    for chunk in RrdReader(rrd).stream():
        entity = str(chunk.entity_path)
        batch = chunk.to_record_batch()
        logged[entity] = logged.get(entity, 0) + chunk.num_rows
        names.update(f.name for f in batch.schema if (f.metadata or {}).get(b"rerun:kind") == b"index")
        if "Pinhole:parent_frame" in batch.schema.names:
            frame = batch.column("Pinhole:parent_frame").to_pylist()[-1][0]
            width, height = batch.column("Pinhole:resolution").to_pylist()[-1][0]
            box = recorded_bounds(rrd) if entity == "/camera" else (0.0, float(width), 0.0, float(height))
            cameras[entity] = (frame, entity, box)
    stamps = "episode_time" if "episode_time" in names else "sensor_time"
    timelines = [stamps, *(t for t in ("log_time", "obs_index", "wall_time") if t in names)]
    return logged, [cameras[e] for e in sorted(cameras, key=lambda e: (e != "/camera", e))], timelines


def recorded_curves(rrd: Path) -> list[str]:
    """The error-against-size curves the recording holds (``/curves/<fault>_<hop>``), latency first."""
    from rerun.chunk import RrdReader

    paths = {str(chunk.entity_path).rsplit("/", 1)[0] for chunk in RrdReader(rrd).stream().filter(content="/curves/**")}
    return sorted(paths, key=lambda p: ("latency" not in p, p))


def recorded_bounds(rrd: Path) -> tuple[float, float, float, float] | None:
    """The camera view's bounds from the recording's own blueprint (its default blueprint store)."""
    from rerun.chunk import RrdReader

    reader = RrdReader(rrd)
    for store in reader.blueprints():
        for chunk in reader.stream(store=store):
            batch = chunk.to_record_batch()
            for name in batch.schema.names:
                if name.endswith("VisualBounds2D:range"):
                    value = batch.column(name).to_pylist()[-1][0]
                    (u0, u1), (v0, v1) = value["x_range"], value["y_range"]
                    return float(u0), float(u1), float(v0), float(v1)
    return None


def recorded_window(rrd: Path) -> float | None:
    """The seconds the series show either side of the cursor, from the recording's own blueprint (None: all)."""
    from rerun.chunk import RrdReader

    reader = RrdReader(rrd)
    for store in reader.blueprints():
        for chunk in reader.stream(store=store):
            batch = chunk.to_record_batch()
            if "TimeAxis:view_range" in batch.schema.names:
                return float(batch.column("TimeAxis:view_range").to_pylist()[-1][0]["end"]) / 1e9
    return None


#: A picture of the loaded viewer with data compresses to well over this (empty viewer: ~25 kB, the
#: loading screen: ~10 kB; the demo: ~240 kB).
MIN_PICTURE_BYTES = 60_000


def not_ready(png: Path) -> str | None:
    """Why ``png`` is not a picture of the loaded viewer with data (None: it is).

    Headless Chromium's virtual time runs out early on a busy machine: the shot then shows the
    dark loading screen or a viewer with no recording yet.
    """
    from PIL import Image

    with Image.open(png) as img:
        grey = np.asarray(img.convert("L"), dtype=np.uint8)
    if (grey > 200).mean() < 0.4:
        return "the page was still loading (mostly dark)"
    if png.stat().st_size < MIN_PICTURE_BYTES:
        return "the viewer shows no recording yet"
    return None


def screenshot(rrd: Path, out: Path, blueprint: Path | None, *, size: tuple[int, int], chromium: str,
               settle_s: float, timeout_s: float) -> None:
    """Serve ``rrd`` to the web viewer, open it in headless Chromium, write ``out`` once it shows data."""
    web_port, grpc_port, debug_port = free_port(), free_port(), free_port()
    files = [str(rrd)] + ([str(blueprint)] if blueprint else [])
    server = subprocess.Popen(
        [str(RERUN), *files, "--serve-web", "--web-viewer-port", str(web_port), "--port", str(grpc_port)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
    )
    browser: subprocess.Popen[bytes] | None = None
    try:
        page = f"http://127.0.0.1:{web_port}"
        _wait_http(page, timeout_s=30)
        source = f"rerun+http://127.0.0.1:{grpc_port}/proxy"
        url = f"{page}/?url={urllib.parse.quote(source, safe='')}&renderer=webgl"
        with tempfile.TemporaryDirectory() as profile:
            browser = subprocess.Popen(
                [chromium, "--headless", "--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader",
                 "--enable-unsafe-swiftshader", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run", f"--user-data-dir={profile}",
                 f"--remote-debugging-port={debug_port}", f"--window-size={size[0]},{size[1]}", url],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
            )
            with DevTools.connect(debug_port, timeout_s=30) as tools:
                # the viewport, not the window (whose frame takes part of --window-size)
                tools.call("Emulation.setDeviceMetricsOverride",
                           {"width": size[0], "height": size[1], "deviceScaleFactor": 1, "mobile": False})
                started = time.monotonic()
                while True:
                    time.sleep(5)
                    out.write_bytes(tools.screenshot())
                    why = not_ready(out)
                    if why is None:
                        break
                    if time.monotonic() - started > timeout_s:
                        raise SystemExit(f"screenshots: {rrd}: {why} after {timeout_s:.0f} s")
                time.sleep(settle_s)  # images are decoded asynchronously after the viewer shows the data
                out.write_bytes(tools.screenshot())
            os.killpg(browser.pid, signal.SIGTERM)
            browser.wait(timeout=10)
    finally:
        if browser is not None and browser.poll() is None:
            os.killpg(browser.pid, signal.SIGTERM)
        # `.venv/bin/rerun` is a wrapper that starts the viewer binary: stop its whole process group.
        os.killpg(server.pid, signal.SIGTERM)
        server.wait(timeout=10)
    print(f"wrote {out}")


def _wait_http(url: str, *, timeout_s: float) -> bytes:
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            body: bytes = urllib.request.urlopen(url, timeout=2).read()
            return body
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.3)


class DevTools:
    """Just enough of the Chrome DevTools Protocol over a WebSocket to take screenshots.

    A hand-written client (RFC 6455 framing: masked client frames, fragmented server frames) so the
    script needs nothing beyond the standard library and Pillow.
    """

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.next_id = 0

    @classmethod
    def connect(cls, port: int, *, timeout_s: float) -> DevTools:
        deadline = time.monotonic() + timeout_s
        while True:
            targets = json.loads(_wait_http(f"http://127.0.0.1:{port}/json/list", timeout_s=timeout_s))
            pages = [t for t in targets if t.get("type") == "page" and t.get("webSocketDebuggerUrl")]
            if pages:
                break
            if time.monotonic() > deadline:
                raise SystemExit("screenshots: Chromium opened no page")
            time.sleep(0.3)
        parts = urllib.parse.urlsplit(pages[0]["webSocketDebuggerUrl"])
        sock = socket.create_connection((parts.hostname, parts.port), timeout=120)
        key = base64.b64encode(os.urandom(16)).decode()
        sock.sendall((f"GET {parts.path} HTTP/1.1\r\nHost: {parts.hostname}:{parts.port}\r\nUpgrade: websocket\r\n"
                      f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            head += sock.recv(1)
        if b" 101 " not in head.split(b"\r\n", 1)[0]:
            raise SystemExit(f"screenshots: DevTools refused the WebSocket: {head.splitlines()[0]!r}")
        return cls(sock)

    def __enter__(self) -> DevTools:
        return self

    def __exit__(self, *exc: object) -> None:
        self.sock.close()

    def call(self, method: str, params: dict[str, object] | None = None) -> dict[str, object]:
        self.next_id += 1
        self._send(json.dumps({"id": self.next_id, "method": method, "params": params or {}}).encode())
        while True:
            message = json.loads(self._receive())
            if message.get("id") == self.next_id:
                if "error" in message:
                    raise SystemExit(f"screenshots: {method}: {message['error']}")
                result: dict[str, object] = message["result"]
                return result

    def screenshot(self) -> bytes:
        return base64.b64decode(str(self.call("Page.captureScreenshot", {"format": "png"})["data"]))

    def _send(self, payload: bytes) -> None:
        n = len(payload)
        if n < 126:
            header = struct.pack("!BB", 0x81, 0x80 | n)
        elif n < 1 << 16:
            header = struct.pack("!BBH", 0x81, 0x80 | 126, n)
        else:
            header = struct.pack("!BBQ", 0x81, 0x80 | 127, n)
        mask = os.urandom(4)
        masked = (np.frombuffer(payload, dtype=np.uint8) ^ np.resize(np.frombuffer(mask, dtype=np.uint8), n)).tobytes()
        self.sock.sendall(header + mask + masked)

    def _exact(self, n: int) -> bytes:
        data = bytearray()
        while len(data) < n:
            chunk = self.sock.recv(n - len(data))
            if not chunk:
                raise SystemExit("screenshots: DevTools closed the connection")
            data += chunk
        return bytes(data)

    def _receive(self) -> bytes:
        parts: list[bytes] = []
        while True:
            first, second = self._exact(2)
            length = second & 0x7F
            if length == 126:
                length = struct.unpack("!H", self._exact(2))[0]
            elif length == 127:
                length = struct.unpack("!Q", self._exact(8))[0]
            data = self._exact(length)
            opcode = first & 0x0F
            if opcode == 0x8:
                raise SystemExit("screenshots: DevTools closed the connection")
            if opcode in (0x9, 0xA):  # ping, pong
                continue
            parts.append(data)
            if first & 0x80:
                return b"".join(parts)


def demo_recording(workdir: Path) -> Path:
    """``framechain demo`` into ``workdir``; returns its .rrd."""
    subprocess.run([str(ROOT / ".venv" / "bin" / "framechain"), "demo", "--out", str(workdir), "-q"], check=True,
                   stdout=subprocess.DEVNULL)
    return workdir / "episode.rrd"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--demo", metavar="OUT.png", help="run `framechain demo` and screenshot its recording")
    what.add_argument("--rrd", type=Path, help="a framechain recording to screenshot (with --out)")
    parser.add_argument("--out", type=Path, help="the PNG (with --rrd)")
    parser.add_argument("--body", default="base_link")
    parser.add_argument("--world", default="map")
    parser.add_argument("--curves-first", action="store_true",
                        help="show the error-against-size curves before the per-hop error (static targets)")
    parser.add_argument("--blueprint", type=Path, metavar="VIEW.rbl",
                        help="a blueprint file to use as it is (a batch's recording view writes FILE.rbl beside it)")
    parser.add_argument("--size", default="1600x900")
    parser.add_argument("--settle", type=float, default=20.0, metavar="S",
                        help="seconds to wait once the data shows, for images to decode (default 20)")
    parser.add_argument("--timeout", type=float, default=300.0, metavar="S",
                        help="give up when the viewer shows no data after this long (default 300)")
    args = parser.parse_args(argv)
    chromium = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if chromium is None:
        print("screenshots: no chromium on PATH (apt-get install chromium)", file=sys.stderr)
        return 1
    width, height = (int(x) for x in args.size.lower().split("x"))
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        if args.demo:
            rrd, out = demo_recording(work / "demo"), Path(args.demo)
        else:
            if args.out is None:
                parser.error("--rrd needs --out")
            rrd, out = args.rrd, args.out
        blueprint: Path | None = args.blueprint
        if blueprint is None:
            blueprint = work / "view.rbl"
            write_blueprint(blueprint, rrd, body=args.body, world=args.world, curves_first=args.curves_first)
        out.parent.mkdir(parents=True, exist_ok=True)
        screenshot(rrd, out, blueprint, size=(width, height), chromium=chromium, settle_s=args.settle,
                   timeout_s=args.timeout)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
