"""Forward kinematics per second: framechain's batched NumPy FK against yourdfpy (and pinocchio).

The 6-revolute-joint test arm (``tests/helpers/data/arm6.urdf``, its prismatic gripper held
fixed) and the SO-101 (5 arm joints + gripper, from ../shared/realdata when present). Every
library computes ``T_base_wrist_camera_link`` (SO-101: ``T_base_gripper_frame_link``) for the same
random joint vectors; results are checked against each other before timing. framechain runs the
whole batch at once (one episode = one batch); yourdfpy and pinocchio one configuration at a
time, as their APIs work. pinocchio runs only when ``pin`` is installed (it is not a dependency).
Prints rates and ratios; asserts nothing about time.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from framechain.robot.kinematics import RobotModel

HERE = Path(__file__).resolve().parent
ARM6 = HERE.parent / "tests" / "helpers" / "data" / "arm6.urdf"
SO101 = HERE.parent.parent / "shared" / "realdata" / "urdf" / "so101" / "so101_new_calib.urdf"
SEED = 20261122
N_BATCH = 200_000
N_SINGLE = 2_000
N_PIN = 50_000

FloatArray = npt.NDArray[np.float64]


def _best_of(fn: Callable[[], object], repeats: int = 5) -> float:
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def bench_robot(urdf: Path, tip: str, rng: np.random.Generator) -> None:
    import yourdfpy

    model = RobotModel.from_urdf(urdf)
    path = model.path_joints(tip)
    moving = [j for j in path if j.moves]
    lower = np.array([j.lower if j.lower is not None else -np.pi for j in moving])
    upper = np.array([j.upper if j.upper is not None else np.pi for j in moving])
    q = rng.uniform(lower, upper, size=(N_BATCH, len(moving)))
    q_path = np.zeros((N_BATCH, len(path)))
    q_path[:, [i for i, j in enumerate(path) if j.moves]] = q

    # Reference: yourdfpy, one configuration at a time.
    urdf_ref = yourdfpy.URDF.load(str(urdf), load_meshes=False, build_collision_scene_graph=False)
    names = [j.name for j in moving]

    def yourdfpy_run(n: int) -> FloatArray:
        out = np.empty((n, 4, 4))
        for i in range(n):
            urdf_ref.update_cfg(dict(zip(names, q[i], strict=True)))
            out[i] = urdf_ref.get_transform(frame_to=tip, frame_from=model.root)
        return out

    ref = yourdfpy_run(200)
    p, quat = model.fk_path(q_path[:200], path)
    R = Rotation.from_quat(quat).as_matrix()
    assert np.allclose(R, ref[:, :3, :3], atol=1e-12)
    assert np.allclose(p, ref[:, :3, 3], atol=1e-12)
    full = model.fk({j.name: q[:200, i] for i, j in enumerate(moving)}, tip, default=0.0)
    assert np.allclose(full, ref, atol=1e-12)

    t_batch = _best_of(lambda: model.fk_path(q_path, path))
    t_batch44 = _best_of(lambda: model.fk({j.name: q[:, i] for i, j in enumerate(moving)}, tip, default=0.0))
    t_single = _best_of(lambda: yourdfpy_run(N_SINGLE), repeats=1)
    rate_batch = N_BATCH / t_batch
    rate_batch44 = N_BATCH / t_batch44
    rate_yourdfpy = N_SINGLE / t_single
    print(f"   {model.name or urdf.stem}: {len(moving)} moving joints to {tip!r} ({len(path)} joints on the path)")
    print(f"     framechain batched (t, q), {N_BATCH} cfgs: {rate_batch:12,.0f} cfg/s")
    print(f"     framechain batched (T,4,4) via fk():      {rate_batch44:12,.0f} cfg/s")
    print(f"     yourdfpy update_cfg + get_transform:       {rate_yourdfpy:12,.0f} cfg/s")
    print(f"     ratio framechain / yourdfpy:               {rate_batch / rate_yourdfpy:12,.0f} x")
    try:
        import pinocchio as pin
    except ImportError:
        print("     pinocchio: not installed (pip install pin), skipped")
        return
    pm = pin.buildModelFromUrdf(str(urdf))
    pd = pm.createData()
    fid = pm.getFrameId(tip)
    # pinocchio orders q by its own joint order; fill by name (all these joints take one entry).
    idx = [pm.joints[pm.getJointId(j.name)].idx_q for j in moving]
    qs = np.zeros((N_PIN, pm.nq))
    qs[:, idx] = q[:N_PIN]

    def pin_run() -> FloatArray:
        out = np.empty((N_PIN, 4, 4))
        for i in range(N_PIN):
            pin.forwardKinematics(pm, pd, qs[i])
            out[i] = pin.updateFramePlacement(pm, pd, fid).homogeneous
        return out

    check = pin_run()[:200]
    assert np.allclose(check, ref, atol=1e-9)
    rate_pin = N_PIN / _best_of(pin_run, repeats=1)
    print(f"     pinocchio forwardKinematics + frame:       {rate_pin:12,.0f} cfg/s")
    print(f"     ratio framechain / pinocchio:              {rate_batch / rate_pin:12,.1f} x")


def main() -> None:
    rng = np.random.default_rng(SEED)
    bench_robot(ARM6, "wrist_camera_link", rng)
    if SO101.is_file():
        bench_robot(SO101, "gripper_frame_link", rng)
    else:
        print(f"   SO-101 URDF not found at {SO101}: skipped")


if __name__ == "__main__":
    main()
