"""Batch throughput: the same fleet of generated logs through ``run_batch`` with 1 and 2 workers.

Each run writes into a fresh output directory (nothing is resumed). Prints, for each, logs per
second overall (the 2-worker figure includes starting the fork server and the workers) and in
steady state (first finished log to last), and the ratios. The CPU seconds per log (measured
inside each unit) and the cores the batch kept busy tell a slow pool from a starved one: on a
machine shared with other sessions (Linux autogroup scheduling shares CPU per session, not per
process) two workers get no more CPU than one.

    python benchmarks/run.py batch                       # 16 logs of 6 s
    FRAMECHAIN_BENCH_BATCH_LOGS=40 python benchmarks/run.py batch
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path
from typing import Any

from framechain.catalogue import Fault
from framechain.fleet import run_batch
from framechain.sim import InjectedFault, SceneSpec, generate, write_scene
from framechain.vision.threads import usable_cpus

FAULTS = (
    InjectedFault(Fault.LATENCY, "robot", {"offset_s": -0.03}),
    InjectedFault(Fault.ROTATION_ERROR, "robot", {"angle_deg": 2.0, "axis": [0.0, 1.0, 0.0]}),
    InjectedFault(Fault.DEPTH_SCALE, "robot", {"factor": 1.05}),
)


def write_fleet(folder: Path, n_logs: int) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(n_logs):
        faults = () if i % 4 == 3 else (FAULTS[i % len(FAULTS)],)
        spec = SceneSpec(seed=100 + i, duration_s=6.0, width=320, height=240, focal_px=300.0, evidence="hops",
                         faults=faults)
        write_scene(generate(spec), folder / f"log_{i:03d}.mcap")


def timed_batch(logs: Path, out: Path, jobs: int) -> dict[str, Any]:
    finished: list[float] = []
    start = time.perf_counter()
    result = run_batch([logs], out, jobs=jobs, report_formats=(),
                       on_record=lambda record: finished.append(time.perf_counter()))
    elapsed = time.perf_counter() - start
    n = len(result.records)
    steady = (n - 1) / (finished[-1] - finished[0]) if n > 1 and finished[-1] > finished[0] else float("nan")
    cpu_s = sum(r["cpu_s"] for r in result.records)
    return {"n": n, "elapsed": elapsed, "overall": n / elapsed, "steady": steady, "cpu_s": cpu_s,
            "statuses": result.status_counts()}


def main() -> None:
    n_logs = int(os.environ.get("FRAMECHAIN_BENCH_BATCH_LOGS", "16"))
    with tempfile.TemporaryDirectory(prefix="framechain-bench-batch-") as tmp:
        root = Path(tmp)
        write_fleet(root / "logs", n_logs)
        load_before = os.getloadavg()[0]
        runs = {jobs: timed_batch(root / "logs", root / f"out_{jobs}", jobs) for jobs in (1, 2)}
        for jobs, r in runs.items():
            print(f"   jobs={jobs}: {r['n']} logs in {r['elapsed']:.2f} s: {r['overall']:.2f} logs/s overall, "
                  f"{r['steady']:.2f} steady; CPU per log {r['cpu_s'] / r['n'] * 1e3:.0f} ms; cores busy "
                  f"{r['cpu_s'] / r['elapsed']:.2f}  {r['statuses']}")
        print(f"   2 workers / 1 worker: x{runs[2]['overall'] / runs[1]['overall']:.2f} overall, "
              f"x{runs[2]['steady'] / runs[1]['steady']:.2f} steady ({usable_cpus()} CPUs usable; load average "
              f"{load_before:.1f} before, {os.getloadavg()[0]:.1f} after: others' work shares the CPUs)")


if __name__ == "__main__":
    main()
