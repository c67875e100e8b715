"""A dataset folder laid out in a Hugging Face cache as huggingface_hub documents it (the "Manage the cache" guide):
``datasets--<owner>--<name>/blobs/<hash>`` holding each file once, ``refs/<branch>`` holding the commit, and
``snapshots/<commit>/<path>`` a relative symlink to its blob."""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable
from pathlib import Path

#: Files the Hub stores with Git LFS (their blob is named by the SHA-256 of the content, others by their git sha1).
_LFS_SUFFIXES = (".parquet", ".mp4")


def put_in_hf_cache(dataset: Path, cache: Path, repo_id: str, *, files: Iterable[str] | None = None,
                    ref: str = "main") -> Path:
    """Put ``files`` of ``dataset`` (paths relative to it; default all) in the cache folder ``cache`` as the Hub
    repository ``repo_id`` at a commit of its own; returns the snapshot folder."""
    names = sorted(files) if files is not None else sorted(
        p.relative_to(dataset).as_posix() for p in dataset.rglob("*") if p.is_file())
    repo = cache / f"datasets--{repo_id.replace('/', '--')}"
    listing = hashlib.sha1()
    blobs: dict[str, str] = {}
    for name in names:
        data = (dataset / name).read_bytes()
        if name.endswith(_LFS_SUFFIXES):
            blob = hashlib.sha256(data).hexdigest()
        else:
            blob = hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()
        blobs[name] = blob
        listing.update(f"{name} {blob}\n".encode())
        (repo / "blobs").mkdir(parents=True, exist_ok=True)
        (repo / "blobs" / blob).write_bytes(data)
    commit = listing.hexdigest()
    snapshot = repo / "snapshots" / commit
    for name, blob in blobs.items():
        link = snapshot / name
        link.parent.mkdir(parents=True, exist_ok=True)
        link.symlink_to(os.path.relpath(repo / "blobs" / blob, link.parent))
    (repo / "refs").mkdir(parents=True, exist_ok=True)
    (repo / "refs" / ref).write_text(commit)
    return snapshot
