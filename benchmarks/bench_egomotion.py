"""Camera-motion evidence on generated SO-101 wrist-video episodes: accuracy over seeds, and time per step.

For each seed: an episode whose video is 80 ms late and whose declared mount is 10 degrees off
(H.264, v3.0), the same motion clean and its copy with the video timestamps 100 ms later, and a
bimanual episode with the camera declared on the other arm; AV1 and MPEG-4 Part 2 episodes for
the decoders. Prints offset error (ms), mount error against the truth and against the injected
10 degrees (deg), whether the link was named, and the seconds spent generating, decoding and
tracking, measuring and fitting. Needs ../shared/realdata/urdf/so101. Asserts nothing.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from framechain.sim.lerobot_video import VideoDatasetSpec, generate_video_dataset  # noqa: E402
from tests.helpers.egomotion_scene import episode_evidence, fit_episode, shifted_copy  # noqa: E402

URDF = HERE.parent.parent / "shared" / "realdata" / "urdf" / "so101" / "so101_new_calib.urdf"
SEEDS = tuple(range(101, 107))
DURATION_S = 5.0


def _one(root: Path, spec: VideoDatasetSpec, label: str, *, shift_s: float = 0.0) -> dict[str, float | str]:
    start = time.perf_counter()
    truth = generate_video_dataset(root / label, spec)
    generated = time.perf_counter()
    data = shifted_copy(truth.root, root / f"{label}_shifted", shift_s) if shift_s else truth.root
    evidence = episode_evidence(truth, URDF, root=data)
    tracked = time.perf_counter()
    fit = fit_episode(evidence, truth)
    fitted = time.perf_counter()
    true_mount = Rotation.from_quat(truth.q_link_cam)
    return {
        "label": label, "link_ok": str(fit.link == truth.camera_link),
        "offset_ms": fit.offset_s * 1e3, "expected_ms": (truth.expected_offset_s - shift_s) * 1e3,
        "interval_ms": (fit.offset_interval_s[1] - fit.offset_interval_s[0]) * 1e3,
        "mount_vs_truth_deg": float(np.rad2deg((Rotation.from_quat(fit.q_link_cam).inv() * true_mount).magnitude())),
        "declared_error_deg": fit.mount_error.angle_deg if fit.mount_error else float("nan"),
        "generate_s": generated - start, "decode_track_s": tracked - generated, "fit_s": fitted - tracked,
    }


def main() -> None:
    if not URDF.is_file():
        print(f"   skipped: {URDF} not found")
        return
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        for seed in SEEDS:
            late = VideoDatasetSpec(URDF, seed=seed, duration_s=DURATION_S, video_delay_s=0.080, mount_error_deg=10.0)
            clean = VideoDatasetSpec(URDF, seed=seed, duration_s=DURATION_S, version="v2.1")
            wrong = VideoDatasetSpec(URDF, seed=seed, duration_s=DURATION_S, bimanual=True, camera_arm="right_",
                                     declared_arm="left_")
            rows.append(_one(root, late, f"late80_mount10_{seed}"))
            rows.append(_one(root, clean, f"clean_{seed}"))
            rows.append(_one(root, clean, f"clean_{seed}_video+100ms", shift_s=0.100))
            rows.append(_one(root, wrong, f"wrong_arm_{seed}"))
            for done in root.iterdir():  # keep the temporary folder small
                shutil.rmtree(done)
        for codec in ("libsvtav1", "mpeg4", "libx265"):
            spec = VideoDatasetSpec(URDF, seed=SEEDS[0], duration_s=DURATION_S, codec=codec, video_delay_s=0.080,
                                    mount_error_deg=10.0)
            rows.append(_one(root, spec, f"late80_mount10_{codec}"))
    print(f"   {'episode':28s} link  offset  expect  err_ms  ci_ms  mount_err  declared  gen_s  track_s  fit_s")
    for r in rows:
        err = float(r["offset_ms"]) - float(r["expected_ms"])
        print(f"   {r['label']:28s} {r['link_ok']:5s} {float(r['offset_ms']):+7.1f} {float(r['expected_ms']):+7.1f} "
              f"{err:+6.1f} {float(r['interval_ms']):6.1f} {float(r['mount_vs_truth_deg']):9.2f} "
              f"{float(r['declared_error_deg']):9.2f} {float(r['generate_s']):6.1f} {float(r['decode_track_s']):8.1f} "
              f"{float(r['fit_s']):6.1f}")
    errors = np.array([float(r["offset_ms"]) - float(r["expected_ms"]) for r in rows])
    mounts = np.array([float(r["mount_vs_truth_deg"]) for r in rows if not str(r["label"]).startswith("wrong")])
    print(f"   offset error: median |e| {np.median(np.abs(errors)):.1f} ms, max {np.abs(errors).max():.1f} ms; "
          f"mount error: median {np.median(mounts):.2f} deg, max {mounts.max():.2f} deg")


if __name__ == "__main__":
    main()
