"""framechain_output: a file framechain wrote is told by its metadata index, found through the summary offsets."""

from __future__ import annotations

from pathlib import Path

from mcap.writer import Writer

from framechain.adapters import framechain_output
from framechain.adapters.formats.mcap.writer import FRAMECHAIN_METADATA


def _mcap(path: Path, *, metadata: dict[str, str] | None, chunks: int = 3, offsets: bool = True) -> Path:
    with path.open("wb") as f:
        writer = Writer(f, chunk_size=64, use_summary_offsets=offsets)
        writer.start(profile="", library="someone else")
        channel = writer.register_channel("/x", "json", writer.register_schema("x", "jsonschema", b"{}"))
        for i in range(chunks * 4):
            writer.add_message(channel, log_time=i, publish_time=i, data=b'{"a": 1}' * 4)
        writer.add_metadata("other", {"k": "v"})
        if metadata is not None:
            writer.add_metadata(FRAMECHAIN_METADATA, metadata)
        writer.finish()
    return path


def test_marked_files_are_told_with_or_without_summary_offsets(tmp_path: Path) -> None:
    record = {"version": "9.9", "command": "export", "source": "/logs/run.bag"}
    for offsets in (True, False):
        marked = _mcap(tmp_path / f"marked_{offsets}.mcap", metadata=record, offsets=offsets)
        plain = _mcap(tmp_path / f"plain_{offsets}.mcap", metadata=None, offsets=offsets)
        assert framechain_output(marked) == "framechain 9.9 export of /logs/run.bag"
        assert framechain_output(plain) is None


def test_a_cut_file_is_not_ours(tmp_path: Path) -> None:
    whole = _mcap(tmp_path / "whole.mcap", metadata={"version": "1", "command": "export"}).read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole[: len(whole) // 2])
    assert framechain_output(cut) is None
