"""A truncated MCAP (no summary, no index): depth frames before the cut are still fetched lazily."""

from __future__ import annotations

from pathlib import Path

from framechain.adapters import open_log
from framechain.replay import replay
from framechain.sim.logs import write_scene
from framechain.sim.scene import SceneSpec, generate


def test_depth_of_a_truncated_mcap_is_fetched(tmp_path: Path) -> None:
    scene = generate(SceneSpec(seed=2, duration_s=3.0, width=160, height=120, focal_px=150.0, depth_images=True))
    full = write_scene(scene, tmp_path / "full.mcap")
    cut = tmp_path / "cut.mcap"
    data = full.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.6)])
    loaded = open_log(cut, scene.chain)
    assert any("recovered" in note for note in loaded.info.notes)
    result = replay(loaded.timeline, scene.chain.frames)
    counts = result.counts()
    assert counts["replayed"] > 0  # observations whose depth frame survived the cut
    assert counts["replayed"] + sum(counts["rejected"].values()) == counts["total"]
    assert set(counts["rejected"]) <= {"no_depth", "extrapolation"}
