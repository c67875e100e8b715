"""Datasets named by their Hugging Face Hub id: generated datasets laid out in a Hugging Face cache as
huggingface_hub documents it, resolved by huggingface_hub's own code in a ``framechain`` process of its own
(the library reads HF_HOME, HF_HUB_CACHE and HF_HUB_OFFLINE when it is imported)."""

from __future__ import annotations

import hashlib
import json
import os
import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import ClassVar

import pytest

from framechain.adapters.lerobot.reader import DatasetReader
from framechain.sim.lerobot_video import VideoDatasetSpec, generate_video_dataset, write_robot_yaml
from tests.helpers.hf_cache import put_in_hf_cache
from tests.helpers.lerobot_scene import write_arm_dataset

DELAY_S = 0.05
V21_EPISODE_0 = ["data/chunk-000/episode_000000.parquet",
                 "videos/chunk-000/observation.images.wrist/episode_000000.mp4"]
V21_META = ["meta/info.json", "meta/episodes.jsonl", "meta/tasks.jsonl", "meta/episodes_stats.jsonl"]


@dataclass(frozen=True)
class HubCache:
    home: Path  # HF_HOME; the cache is HF_HOME/hub
    robot: Path  # robot.yaml of the generated datasets
    v3_snapshot: Path


@pytest.fixture(scope="module")
def hub_cache(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> HubCache:
    """Two 3 s SO-101 episodes whose wrist video is 50 ms late, as ``lerobot/tiny_v3`` (v3.0, whole) and
    ``lerobot/tiny_v21`` (v2.1, only meta/ and episode 0 in the cache)."""
    from huggingface_hub import scan_cache_dir

    folder = tmp_path_factory.mktemp("hub")
    datasets = {}
    for version in ("v3.0", "v2.1"):
        truth = generate_video_dataset(folder / version, VideoDatasetSpec(
            so101_urdf, seed=5, episodes=2, duration_s=3.0, version=version, video_delay_s=DELAY_S))
        datasets[version] = truth
    robot = write_robot_yaml(datasets["v3.0"], folder / "robot.yaml")
    home = folder / "hf"
    snapshot = put_in_hf_cache(folder / "v3.0", home / "hub", "lerobot/tiny_v3")
    put_in_hf_cache(folder / "v2.1", home / "hub", "lerobot/tiny_v21", files=[*V21_META, *V21_EPISODE_0])
    # huggingface_hub's own scan reads the layout as a cache of two dataset repositories.
    scan = scan_cache_dir(home / "hub")
    assert not scan.warnings
    assert {(r.repo_id, r.repo_type, r.nb_files) for r in scan.repos} == {
        ("lerobot/tiny_v3", "dataset", 6), ("lerobot/tiny_v21", "dataset", 6)}
    return HubCache(home, robot, snapshot)


def framechain(*args: str, cwd: Path | None = None, **env: str) -> subprocess.CompletedProcess[str]:
    """``framechain ARGS`` in a process of its own, with the Hugging Face variables of ``env`` alone."""
    base = {k: v for k, v in os.environ.items() if not k.startswith("HF_")}
    return subprocess.run([sys.executable, "-m", "framechain", *args], capture_output=True, text=True,
                          env={**base, "HF_HUB_DISABLE_TELEMETRY": "1", **env}, cwd=cwd, timeout=120, check=False)


def offline(cache: HubCache) -> dict[str, str]:
    return {"HF_HOME": str(cache.home), "HF_HUB_OFFLINE": "1"}


def one_error_line(done: subprocess.CompletedProcess[str]) -> str:
    assert done.returncode == 1, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    return lines[0]


def test_info_and_attribute_read_an_episode_from_the_cache_offline(hub_cache: HubCache, tmp_path: Path) -> None:
    info = framechain("info", "lerobot/tiny_v3", "--episode", "0", "--json", **offline(hub_cache))
    assert info.returncode == 0, info.stderr
    summary = json.loads(info.stdout)
    assert Path(summary["path"]).resolve() == hub_cache.v3_snapshot.resolve()
    assert summary["message_count"] == 90  # 3 s at 30 fps
    done = framechain("attribute", "lerobot/tiny_v3", "--episode", "0", "--robot", str(hub_cache.robot),
                      "--out", str(tmp_path), "--bootstrap", "0", "--format", "json", "-q", **offline(hub_cache))
    assert done.returncode == 0, done.stderr
    top = json.loads((tmp_path / "attribution.json").read_text())["findings"][0]
    assert (top["fault"], top["hop"]) == ("latency", "camera_to_body")
    assert top["estimate"]["offset_s"] == pytest.approx(-DELAY_S, abs=0.01)  # the video's delay, as generated


def test_the_cache_named_by_hf_hub_cache_is_read(hub_cache: HubCache) -> None:
    done = framechain("info", "lerobot/tiny_v21", "--episode", "0", "--json",
                      HF_HUB_CACHE=str(hub_cache.home / "hub"), HF_HUB_OFFLINE="1")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["container"].startswith("lerobot v2.1")


def test_an_id_or_an_episode_not_in_the_cache_is_one_line_offline(hub_cache: HubCache) -> None:
    line = one_error_line(framechain("info", "lerobot/unknown", "--episode", "0", **offline(hub_cache)))
    assert "lerobot/unknown" in line
    assert "not in the Hugging Face cache" in line
    assert "HF_HUB_OFFLINE" in line
    # meta/ and episode 0 are cached, episode 1 is not: its parquet and video are named
    line = one_error_line(framechain("info", "lerobot/tiny_v21", "--episode", "1", **offline(hub_cache)))
    assert "not in the Hugging Face cache" in line
    assert "data/chunk-000/episode_000001.parquet" in line
    # batch without --episodes asks for every episode: the same line, before any episode is attributed
    line = one_error_line(framechain("batch", "lerobot/tiny_v21", "--out", str(hub_cache.home / "fleet"),
                                     **offline(hub_cache)))
    assert "data/chunk-000/episode_000001.parquet" in line


def test_a_local_folder_wins_over_the_hub_id_of_its_name(hub_cache: HubCache, tmp_path: Path) -> None:
    local = tmp_path / "lerobot" / "tiny_v3"
    write_arm_dataset(local, version="v2.1", lengths=(12,))
    done = framechain("info", "lerobot/tiny_v3", "--json", cwd=tmp_path, **offline(hub_cache))
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["container"].startswith("lerobot v2.1 (1 episodes")
    line = one_error_line(framechain("info", "lerobot/tiny_v3", "--revision", "v3.0", cwd=tmp_path,
                                     **offline(hub_cache)))
    assert "--revision" in line
    assert "local path" in line


class _Hub(BaseHTTPRequestHandler):
    """The Hub's HTTP answers as huggingface_hub reads them: a repository's revision and file tree, its files
    (``resolve``), and the errors of a gated and of an unknown repository. ``served``: repository id -> folder;
    ``fetched``: the files whose content was sent."""

    served: ClassVar[dict[str, Path]] = {}
    fetched: ClassVar[list[str]] = []
    commit = "0123456789abcdef0123456789abcdef01234567"

    def do_HEAD(self) -> None:
        self._answer(body=False)

    def do_GET(self) -> None:
        self._answer(body=True)

    def _answer(self, *, body: bool) -> None:
        path = self.path.split("?")[0]
        repo_id = "/".join(path.split("/")[3:5] if path.startswith("/api/") else path.split("/")[2:4])
        folder = self.served.get(repo_id)
        if folder is None:
            self._send(403 if "gated" in repo_id else 404, b"", {"X-Error-Code": "GatedRepo" if "gated" in repo_id
                                                                 else "RepoNotFound"})
        elif "/revision/" in path:
            self._send(200, json.dumps({"id": repo_id, "sha": self.commit, "private": False}).encode(), {})
        elif "/tree/" in path:
            files = [{"type": "file", "path": p.relative_to(folder).as_posix(), "size": p.stat().st_size,
                      "oid": hashlib.sha1(p.read_bytes()).hexdigest()}
                     for p in sorted(folder.rglob("*")) if p.is_file()]
            self._send(200, json.dumps(files).encode(), {})
        else:  # /datasets/<id>/resolve/<commit>/<file>
            name = path.split("/resolve/", 1)[1].split("/", 1)[1]
            data = (folder / name).read_bytes()
            if body:
                self.fetched.append(name)
            etag = f'"{hashlib.sha1(data).hexdigest()}"'
            self._send(200, data if body else b"", {"X-Repo-Commit": self.commit, "ETag": etag,
                                                    "Content-Length": str(len(data))}, length=False)

    def _send(self, code: int, data: bytes, headers: dict[str, str], *, length: bool = True) -> None:
        self.send_response(code)
        for key, value in headers.items():
            self.send_header(key, value)
        if length:
            self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data)

    def log_message(self, *args: object) -> None:
        pass


@pytest.fixture(scope="module")
def fake_hub() -> Iterator[str]:
    server = ThreadingHTTPServer(("127.0.0.1", 0), _Hub)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()


def test_only_meta_and_the_episodes_asked_for_are_fetched(hub_cache: HubCache, fake_hub: str,
                                                          tmp_path: Path) -> None:
    dataset = tmp_path / "served"
    write_arm_dataset(dataset, version="v2.1", lengths=(8, 9, 10))
    _Hub.served["someone/served_set"] = dataset
    _Hub.fetched.clear()
    home = tmp_path / "hf"
    done = framechain("info", "someone/served_set", "--episode", "1", "--json", HF_HOME=str(home),
                      HF_ENDPOINT=fake_hub)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["message_count"] == 9
    meta = sorted(p.relative_to(dataset).as_posix() for p in (dataset / "meta").iterdir())
    assert sorted(_Hub.fetched) == sorted([*meta, "data/chunk-000/episode_000001.parquet"])  # no video was written
    # the episode is in the user's cache now: offline, it is read from there
    again = framechain("info", "someone/served_set", "--episode", "1", "--json", HF_HOME=str(home),
                       HF_HUB_OFFLINE="1")
    assert again.returncode == 0, again.stderr


def test_gated_unknown_and_unreachable_are_one_line_each(hub_cache: HubCache, fake_hub: str) -> None:
    online = {"HF_HOME": str(hub_cache.home), "HF_ENDPOINT": fake_hub}
    line = one_error_line(framechain("info", "someone/gated_set", "--episode", "0", **online))
    assert "gated" in line
    assert "https://huggingface.co/datasets/someone/gated_set" in line
    line = one_error_line(framechain("info", "someone/no_such_set", "--episode", "0", **online))
    assert "no dataset of that id on the Hugging Face Hub" in line
    with socket.socket() as probe:  # a port nothing listens on
        probe.bind(("127.0.0.1", 0))
        closed = f"http://127.0.0.1:{probe.getsockname()[1]}"
    line = one_error_line(framechain("info", "someone/other_set", "--episode", "0",
                                     HF_HOME=str(hub_cache.home), HF_ENDPOINT=closed))
    assert "cannot be reached" in line
    assert "not in the cache" in line


@pytest.mark.parametrize("version", ["v2.1", "v3.0"])
def test_episode_patterns_name_the_files_the_writer_wrote(version: str, tmp_path: Path) -> None:
    """Each episode's data file and video as the writer names them (LeRobot's templates, filled by hand); in
    v3.0 two episodes share a file."""
    dataset = write_arm_dataset(tmp_path / "ds", version=version, lengths=(5, 6, 7), episodes_per_file=2
                                if version == "v3.0" else None)
    reader = DatasetReader(dataset.root)
    key = "observation.images.wrist"
    for episode in range(3):
        if version == "v2.1":
            expected = [f"data/chunk-000/episode_{episode:06d}.parquet",
                        f"videos/chunk-000/{key}/episode_{episode:06d}.mp4"]
        else:
            expected = [f"data/chunk-000/file-{episode // 2:03d}.parquet",
                        f"videos/{key}/chunk-000/file-{episode // 2:03d}.mp4"]
        assert reader.episode_patterns(episode) == expected
        assert (dataset.root / expected[0]).is_file()
