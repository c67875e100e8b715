"""Screenshots of the real Rerun viewer on framechain recordings (slow: not part of the tests).

How: ``rerun REC.rrd VIEW.rbl --serve-web`` hosts the web viewer and serves the recording over
gRPC; headless Chromium renders it with SwiftShader (WebGL on the CPU; no GPU, no display) and
writes a PNG. The blueprint ``VIEW.rbl`` is framechain's default with the side panels collapsed.
The viewer opens at the end of the timeline: the shot shows the last observation.

Measured on a busy 2-core machine: 20 s to 2.5 min per screenshot. The virtual-time budget matters:
20 s of page time showed a loading spinner where the JPEG goes (images are decoded asynchronously);
60 s shows it; 90 s and more gave an empty viewer with Chromium 156 (the page never connected).
A native viewer under Xvfb with llvmpipe gave all-black captures on this machine.

    .venv/bin/python scripts/screenshots.py --demo docs/images/demo_viewer.png
    .venv/bin/python scripts/screenshots.py --rrd aruco.rrd --camera raspicam --out docs/images/aruco_viewer.png

Needs ``chromium`` on PATH (Debian: ``apt-get install chromium``).
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RERUN = ROOT / ".venv" / "bin" / "rerun"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def write_blueprint(path: Path, camera: str, body: str, world: str, *, images: bool,
                    bounds: tuple[float, float, float, float] | None) -> None:
    """framechain's default blueprint with the side panels collapsed, for application ``framechain``."""
    from framechain.sinks.rerun import default_blueprint
    from framechain.timeline import ChainFrames

    blueprint = default_blueprint(ChainFrames(camera=camera, body=body, world=world), images=images,
                                  collapse_panels=True, image_bounds=bounds)
    blueprint.save("framechain", path)


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


def screenshot(rrd: Path, out: Path, blueprint: Path | None, *, size: tuple[int, int],
               budget_ms: int, chromium: str) -> None:
    """Serve ``rrd`` to the web viewer, render it in headless Chromium, write ``out``."""
    web_port, grpc_port = free_port(), free_port()
    files = [str(rrd)] + ([str(blueprint)] if blueprint else [])
    server = subprocess.Popen(
        [str(RERUN), *files, "--serve-web", "--web-viewer-port", str(web_port), "--port", str(grpc_port)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
    )
    try:
        page = f"http://127.0.0.1:{web_port}"
        for _ in range(100):
            try:
                urllib.request.urlopen(page, timeout=1).read(64)
                break
            except OSError:
                time.sleep(0.2)
        source = f"rerun+http://127.0.0.1:{grpc_port}/proxy"
        url = f"{page}/?url={urllib.parse.quote(source, safe='')}&renderer=webgl"
        with tempfile.TemporaryDirectory() as profile:
            subprocess.run(
                [chromium, "--headless", "--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader",
                 "--enable-unsafe-swiftshader", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run", f"--user-data-dir={profile}", f"--screenshot={out}",
                 f"--window-size={size[0]},{size[1]}", f"--virtual-time-budget={budget_ms}", url],
                check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=budget_ms / 1000 + 120,
            )
    finally:
        # `.venv/bin/rerun` is a wrapper that starts the viewer binary: stop its whole process group.
        os.killpg(server.pid, signal.SIGTERM)
        server.wait(timeout=10)
    print(f"wrote {out}")


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
    parser.add_argument("--camera", default="camera_optical_frame", help="the chain's camera frame")
    parser.add_argument("--body", default="base_link")
    parser.add_argument("--world", default="map")
    parser.add_argument("--no-images", action="store_true", help="the recording has no camera images")
    parser.add_argument("--size", default="1600x900")
    parser.add_argument("--budget-ms", type=int, default=60_000,
                        help="page time Chromium runs before the shot (default 60000; more broke the page)")
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
        blueprint = work / "view.rbl"
        write_blueprint(blueprint, args.camera, args.body, args.world, images=not args.no_images,
                        bounds=recorded_bounds(rrd))
        out.parent.mkdir(parents=True, exist_ok=True)
        screenshot(rrd, out, blueprint, size=(width, height), budget_ms=args.budget_ms, chromium=chromium)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
