"""framechain's one way to read Parquet and Arrow columns without pandas: ``read_parquet`` against pyarrow's own
``pq.read_table`` (with its filters), ``numpy_of`` against pyarrow's own ``to_numpy``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from framechain.timeline import numpy_of, read_parquet


@pytest.mark.parametrize("values", [
    pa.array([3, -1, 7, 0], pa.int64()), pa.array([1, 2, 250], pa.uint8()), pa.array([5, -6], pa.int16()),
    pa.array([0.5, -2.25, 1e300], pa.float64()), pa.array([1.5, 3.0], pa.float32()),
    pa.array([True, False, True, True, False, False, True, False, True], pa.bool_()),
])
def test_numpy_of_numbers_and_booleans_as_pyarrow_reads_them(values: pa.Array) -> None:
    for part in (values, values.slice(1), values.slice(1, 1), values.slice(len(values))):
        mine = numpy_of(part)
        theirs = part.to_numpy(zero_copy_only=False)
        assert mine.dtype == theirs.dtype
        assert np.array_equal(mine, theirs)


def test_numpy_of_chunks_nulls_and_other_types() -> None:
    chunked = pa.chunked_array([pa.array([1.0, 2.0]), pa.array([3.0]).slice(0, 1), pa.array([], pa.float64())])
    assert np.array_equal(numpy_of(chunked), [1.0, 2.0, 3.0])
    with_nulls = pa.array([4, None, 6, None, 8], pa.int32()).slice(1)
    np.testing.assert_array_equal(numpy_of(with_nulls), [np.nan, 6.0, np.nan, 8.0])
    assert np.array_equal(numpy_of(pa.array(["a", "bc"])), ["a", "bc"])
    assert numpy_of(pa.chunked_array([], pa.int64())).dtype == np.int64
    nested = pa.array([[1.0, 2.0], [3.0, 4.0]], pa.list_(pa.float64()))
    assert np.array_equal(numpy_of(nested.flatten()), [1.0, 2.0, 3.0, 4.0])


@pytest.mark.parametrize("columns", [None, ["value"], ["episode_index", "value"]])
def test_read_parquet_rows_of_one_value_as_pyarrow_filters_them(tmp_path: Path, columns: list[str] | None) -> None:
    path = tmp_path / "episodes.parquet"
    episode = np.repeat(np.arange(6), 50)
    table = pa.table({"episode_index": episode, "value": np.arange(episode.size) * 0.5})
    pq.write_table(table, path, row_group_size=64)  # row groups that hold one, two or three episodes
    for wanted in (0, 3, 5, 9):
        mine = read_parquet(path, columns, where_equal=("episode_index", wanted))
        theirs = pq.read_table(path, columns=columns, filters=[("episode_index", "=", wanted)])
        assert mine.column_names == theirs.column_names
        assert mine.to_pylist() == theirs.to_pylist()
        assert mine.num_rows == (50 if wanted < 6 else 0)
    assert read_parquet(path).to_pylist() == pq.read_table(path).to_pylist()


def test_reading_a_lerobot_episode_does_not_import_pandas(tmp_path: Path) -> None:
    """What the two are for: pandas (0.15 s of every command) is not imported to read an episode's rows, here from
    a v3 data file holding three episodes."""
    from framechain.adapters.lerobot.writer import EpisodeData, FeatureSpec, write_lerobot_dataset

    state = FeatureSpec("float32", (2,), ["a", "b"])
    episodes = [EpisodeData({"observation.state": np.full((n, 2), e, dtype=np.float32)}) for e, n in
                enumerate((12, 20, 7))]
    root = write_lerobot_dataset(tmp_path / "ds", episodes, features={"observation.state": state}, fps=10)
    script = ("import sys; from framechain.adapters.lerobot.reader import DatasetReader; "
              f"f = DatasetReader({str(root)!r}).read(1, ['observation.state']); "
              "print(len(f), f.columns['observation.state'].shape, set(f.columns['observation.state'].ravel()), "
              "'pandas' in sys.modules, 'pyarrow.dataset' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "20 (20, 2) {np.float32(1.0)} False False"
