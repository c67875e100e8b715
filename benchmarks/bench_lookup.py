"""Batched chain lookups per second: framechain's TransformBuffer against pytransform3d.

One 6-frame tree, ``map -> odom -> base_link -> torso -> camera_link -> camera_optical``: two
dynamic edges (map -> odom, odom -> base_link) sampled at 100 Hz over 10 minutes, three static
edges. Both libraries answer the same 1e6 query times (random, inside the recorded span) for the
whole chain ``T_map_camera_optical``; both results are checked against each other at the
sample stamps before timing. Prints both rates and their ratio; asserts nothing about time.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from framechain.replay import TransformBuffer
from framechain.timeline import TransformTable

RATE_HZ = 100
DURATION_S = 600
N_QUERIES = 1_000_000
SEED = 20261122
TARGET, SOURCE = "map", "camera_optical"

FloatArray = npt.NDArray[np.float64]


def make_tree() -> dict[tuple[str, str], tuple[bool, FloatArray, FloatArray]]:
    """Edges ``(parent, child) -> (is_static, translation (n, 3), quat_xyzw (n, 4))``."""
    n = RATE_HZ * DURATION_S
    t = np.arange(n) / RATE_HZ
    yaw = 0.3 * t + 0.2 * np.sin(0.5 * t)
    drift = Rotation.from_rotvec(np.outer(1e-4 * t, [0.0, 0.0, 1.0]))
    odom = Rotation.from_euler("xyz", np.stack([0.05 * np.sin(t), 0.03 * np.cos(0.7 * t), yaw], axis=1))
    return {
        ("map", "odom"): (False, np.stack([1e-3 * t, -5e-4 * t, np.zeros(n)], axis=1), drift.as_quat()),
        ("odom", "base_link"): (
            False, np.stack([np.cos(0.1 * t), np.sin(0.1 * t), 0.01 * np.sin(t)], axis=1) * 5, odom.as_quat()
        ),
        ("base_link", "torso"): (True, np.array([[0.1, 0.0, 0.6]]), np.array([[0.0, 0.0, 0.0, 1.0]])),
        ("torso", "camera_link"): (
            True, np.array([[0.2, 0.05, 0.3]]), Rotation.from_euler("y", 0.3).as_quat()[None, :]
        ),
        ("camera_link", "camera_optical"): (
            True, np.zeros((1, 3)), np.array([[-0.5, 0.5, -0.5, 0.5]])
        ),
    }


def stamps_ns() -> npt.NDArray[np.int64]:
    return np.arange(RATE_HZ * DURATION_S, dtype=np.int64) * (1_000_000_000 // RATE_HZ)


def build_framechain(tree: dict[tuple[str, str], tuple[bool, FloatArray, FloatArray]]) -> TransformBuffer:
    parts = []
    for (parent, child), (static, trans, quat) in tree.items():
        stamps = np.zeros(1, dtype=np.int64) if static else stamps_ns()
        parts.append(TransformTable.from_rows(parent, child, stamps, trans, quat, is_static=static))
    return TransformBuffer(TransformTable.concat(parts))


def build_pytransform3d(tree: dict[tuple[str, str], tuple[bool, FloatArray, FloatArray]]) -> object:
    from pytransform3d.transform_manager import (
        NumpyTimeseriesTransform,
        StaticTransform,
        TemporalTransformManager,
    )

    tm = TemporalTransformManager()
    seconds = stamps_ns() * 1e-9
    for (parent, child), (static, trans, quat) in tree.items():
        pqs = np.concatenate([trans, quat[:, [3, 0, 1, 2]]], axis=1)  # pytransform3d: x y z qw qx qy qz
        if static:
            matrix = np.eye(4)
            matrix[:3, :3] = Rotation.from_quat(quat[0]).as_matrix()
            matrix[:3, 3] = trans[0]
            tm.add_transform(child, parent, StaticTransform(matrix))
        else:
            tm.add_transform(child, parent, NumpyTimeseriesTransform(seconds, pqs))
    return tm


def best_rates(fn: Callable[[], object], n: int, repeats: int) -> tuple[float, float]:
    """Lookups per second of the fastest of ``repeats`` runs: by wall-clock time and by CPU time.

    The machine is shared: CPU time (of this process, all threads) is the steadier figure.
    """
    wall, cpu = np.inf, np.inf
    for _ in range(repeats):
        start_wall, start_cpu = time.perf_counter(), time.process_time()
        fn()
        wall = min(wall, time.perf_counter() - start_wall)
        cpu = min(cpu, time.process_time() - start_cpu)
    return n / wall, n / cpu


def main() -> None:
    rng = np.random.default_rng(SEED)
    tree = make_tree()
    buffer = build_framechain(tree)
    tm = build_pytransform3d(tree)
    span = stamps_ns()
    times_ns = rng.integers(span[0], span[-1], size=N_QUERIES, endpoint=True)
    times_s = times_ns * 1e-9

    # Same answer at the sample stamps (where ScLERP and lerp/slerp coincide) before timing.
    check = span[:: RATE_HZ * 7]
    ours = buffer.lookup(TARGET, SOURCE, check).matrix()
    theirs = tm.get_transform_at_time(SOURCE, TARGET, check * 1e-9)  # type: ignore[attr-defined]
    worst = float(np.max(np.abs(ours - theirs)))
    if worst > 1e-9:
        raise RuntimeError(f"framechain and pytransform3d disagree at sample stamps by {worst:.3g}")

    fc_wall, fc_cpu = best_rates(lambda: buffer.lookup(TARGET, SOURCE, times_ns), N_QUERIES, repeats=7)
    pt_wall, pt_cpu = best_rates(
        lambda: tm.get_transform_at_time(SOURCE, TARGET, times_s),  # type: ignore[attr-defined]
        N_QUERIES, repeats=3,
    )
    n_samples = RATE_HZ * DURATION_S
    print(f"   6-frame tree, 2 dynamic edges x {n_samples} samples ({RATE_HZ} Hz, {DURATION_S} s), "
          f"{N_QUERIES:.0e} random query times, chain {SOURCE} -> {TARGET}")
    print(f"   {'':47s} {'CPU time':>16s} {'wall clock':>16s}")
    print(f"   framechain     TransformBuffer.lookup          {fc_cpu:12,.0f} /s {fc_wall:12,.0f} /s")
    print(f"   pytransform3d  get_transform_at_time (batched) {pt_cpu:12,.0f} /s {pt_wall:12,.0f} /s")
    print(f"   ratio framechain / pytransform3d               {fc_cpu / pt_cpu:12.1f} x  {fc_wall / pt_wall:12.1f} x")

if __name__ == "__main__":
    main()
