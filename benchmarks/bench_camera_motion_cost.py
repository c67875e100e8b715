"""What the cameras' own motion costs the user, side by side with decoding their videos, and a whole recording's batch.

1. ``framechain attribute`` on one episode, from process start to exit (reports written), against a process
   that only decodes the episode's videos with PyAV (every frame to grey: the floor of any image-based
   method), taken in turn, the least of ``ROUNDS`` each: a 224x224 MPEG-4 two-camera episode recorded as
   real recorders do (15 s at ~18.6 Hz) and a 640x480 AV1 one-camera episode (15 s at 30 fps). The rounds
   find the URDF parsed already (framechain's cache, as every run after a robot's first does); the first
   run, which parses it (yourdfpy and trimesh imported: about 0.4 s more), is printed beside them. Each command's
   CPU time (its processes' user and system time, renderers included) is printed too, and what it implies: the
   least wall time that work could take spread perfectly over this machine's cores, and the ratio that would give.
2. ``framechain batch`` (2 workers) on a 25-episode two-camera recording of 15 s episodes, end to end.

Generated with :mod:`framechain.sim.lerobot_video`; needs ../shared/realdata/urdf/so101. Prints figures and
ratios; asserts nothing. ``FRAMECHAIN_BENCH_EPISODES`` shortens the recording (default 25).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from framechain.robot.urdf import CACHE_ENV
from framechain.vision.threads import usable_cpus

HERE = Path(__file__).resolve().parent
URDF = HERE.parent.parent / "shared" / "realdata" / "urdf" / "so101" / "so101_new_calib.urdf"
ROUNDS = 3
EPISODES = int(os.environ.get("FRAMECHAIN_BENCH_EPISODES", "25"))
FRAMECHAIN = str(Path(sys.executable).with_name("framechain"))
#: The timed commands run as a user's would, without MALLOC_PERTURB_ (glibc filling every allocation and every free
#: costs framechain's NumPy temporaries about 10% of an episode); the episodes are generated in a process with it,
#: as the tests generate theirs, so that the encoders write the same videos every run (see the Makefile). framechain's
#: modules are compiled to bytecode first (:func:`_compiled`), as an installed package's are: a machine that sets
#: PYTHONDONTWRITEBYTECODE would otherwise compile them from source in every run (0.18 s).
ENV = {name: value for name, value in os.environ.items() if name != "MALLOC_PERTURB_"}

DECODE = """
import sys, av
from pathlib import Path
for path in sorted(Path(sys.argv[1]).rglob("*.mp4")):
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        for frame in container.decode(stream):
            frame.to_ndarray(format="gray")
"""


def _generate(root: Path, kind: str, episodes: int = 1) -> tuple[Path, Path]:
    """The dataset and its robot.yaml under ``root``, written by a process of their own with MALLOC_PERTURB_."""
    subprocess.run([sys.executable, __file__, "--generate", str(root), kind, str(episodes)], check=True,
                   env={**os.environ, "MALLOC_PERTURB_": "165"})
    return root / "dataset", root / "robot.yaml"


def _generate_here(root: Path, kind: str, episodes: int) -> None:
    from framechain.sim.lerobot_video import VideoDatasetSpec, generate_video_dataset, write_robot_yaml

    spec = (VideoDatasetSpec(URDF, seed=3, episodes=episodes, duration_s=15.0, fps=20, codec="mpeg4", bimanual=True,
                             camera_per_arm=True, clock="realtime", focal_px=112.0, repeat_share=0.15,
                             camera_delays_s=(0.06, 0.09))
            if kind == "mpeg4" else
            VideoDatasetSpec(URDF, seed=3, episodes=episodes, duration_s=15.0, fps=30, codec="libsvtav1", width=640,
                             height=480, focal_px=500.0, video_delay_s=0.05))
    write_robot_yaml(generate_video_dataset(root / "dataset", spec), root / "robot.yaml")


def _seconds(argv: list[str]) -> float:
    return _timed(argv)[0]


def _timed(argv: list[str]) -> tuple[float, float]:
    """Wall time of the command, and the CPU time (user and system) of it and every process it waited for."""
    before = os.times()
    start = time.perf_counter()
    subprocess.run(argv, check=True, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    after = os.times()
    return wall, (after.children_user - before.children_user) + (after.children_system - before.children_system)


def _compiled() -> None:
    """framechain's modules compiled to bytecode (``__pycache__`` beside them), as pip leaves an installed package."""
    import framechain

    subprocess.run([sys.executable, "-m", "compileall", "-q", str(Path(framechain.__file__).parent)], check=True)


def _episode(root: Path, kind: str) -> None:
    dataset, robot = _generate(root / kind, kind)
    attribute = [FRAMECHAIN, "attribute", str(dataset), "--episode", "0", "--robot", str(robot), "--out",
                 str(root / kind / "out"), "-q"]
    decode = [sys.executable, "-c", DECODE, str(dataset)]
    ENV[CACHE_ENV] = str(root / kind / "cache")  # empty: the first run parses the URDF
    first = _seconds(attribute)
    runs = [(_timed(attribute), _timed(decode)) for _ in range(ROUNDS)]
    pairs = [(a[0], d[0]) for a, d in runs]
    best_attribute, best_decode = min(a for a, _ in pairs), min(d for _, d in pairs)
    cpu_attribute, cpu_decode = min(a[1] for a, _ in runs), min(d[1] for _, d in runs)
    cores = usable_cpus()
    print(f"   {kind:6s} episode: attribute {best_attribute:5.2f} s, decoding its videos {best_decode:4.2f} s: "
          f"{best_attribute / best_decode:4.1f}x (rounds: {', '.join(f'{a / d:.1f}x' for a, d in pairs)}; "
          f"the first run, parsing the URDF: {first:.2f} s, {first / best_decode:.1f}x)")
    print(f"          CPU: attribute {cpu_attribute:5.2f} s, decoding {cpu_decode:4.2f} s; that work spread perfectly "
          f"over {cores} cores takes {cpu_attribute / cores:.2f} s at least: "
          f"{cpu_attribute / cores / best_decode:.1f}x")


def main() -> None:
    if not URDF.is_file():
        print(f"   skipped: {URDF} not found")
        return
    _compiled()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        for kind in ("mpeg4", "av1"):
            _episode(root, kind)
        dataset, robot = _generate(root / "recording", "mpeg4", EPISODES)
        seconds = _seconds([FRAMECHAIN, "batch", str(dataset), "--robot", str(robot), "--out", str(root / "batch"),
                            "-j", "2", "-q", "--format", "md"])
        print(f"   batch of a {EPISODES}-episode two-camera recording (15 s episodes, 2 workers): {seconds:.0f} s "
              f"({seconds / EPISODES:.1f} s per episode)")


if __name__ == "__main__":
    if sys.argv[1:2] == ["--generate"]:
        _generate_here(Path(sys.argv[2]), sys.argv[3], int(sys.argv[4]))
    else:
        main()
