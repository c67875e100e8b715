"""``map_forked``: each item's work in a process forked from the caller, results and errors pickled back in order."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from framechain.adapters.errors import AdapterError
from framechain.vision import threads
from framechain.vision.threads import map_forked, threads_here

pytestmark = pytest.mark.skipif(not threads.forks(), reason="map_forked forks on Linux only")


def _pid_and_square(x: int) -> tuple[int, int]:
    return os.getpid(), x * x


def test_each_item_is_worked_in_a_child_and_comes_back_in_order() -> None:
    out = map_forked(_pid_and_square, list(range(7)), 3)
    assert [square for _pid, square in out] == [x * x for x in range(7)]
    pids = {pid for pid, _square in out}
    assert os.getpid() not in pids
    assert len(pids) == 7  # a child per item


def test_at_most_the_given_number_of_children_run_at_once(tmp_path: Path) -> None:
    log = tmp_path / "log"

    def spell(x: int) -> int:  # each child notes when it ran
        start = time.monotonic()
        time.sleep(0.2)
        with log.open("a") as f:
            f.write(f"{start} {time.monotonic()}\n")
        return x

    assert map_forked(spell, list(range(4)), 2) == [0, 1, 2, 3]
    spans = sorted(tuple(map(float, line.split())) for line in log.read_text().splitlines())
    most = max(sum(1 for a, b in spans if a <= t < b) for t, _end in spans)
    assert most == 2


def test_a_result_larger_than_a_pipe_comes_back_whole() -> None:
    big = map_forked(lambda seed: np.random.default_rng(seed).normal(size=(1000, 1000)), [1, 2], 2)
    assert np.array_equal(big[0], np.random.default_rng(1).normal(size=(1000, 1000)))  # 8 MB each
    assert np.array_equal(big[1], np.random.default_rng(2).normal(size=(1000, 1000)))


def test_a_framechain_error_in_a_child_is_raised_here_with_its_type_and_fields() -> None:
    def fail(x: int) -> int:
        if x == 1:
            raise AdapterError("/logs/run.mcap", "cannot decode its images", topic="/camera/image")
        return x

    with pytest.raises(AdapterError) as raised:
        map_forked(fail, [0, 1, 2], 2)
    assert str(raised.value) == str(AdapterError("/logs/run.mcap", "cannot decode its images", topic="/camera/image"))
    assert raised.value.topic == "/camera/image"


class _UnrebuildableError(Exception):
    def __init__(self, a: int, b: int) -> None:
        super().__init__(f"{a} and {b}")


def test_another_library_s_error_that_cannot_be_pickled_comes_back_by_name_and_message() -> None:
    def fail(x: int) -> int:
        raise _UnrebuildableError(x, 2)

    with pytest.raises(RuntimeError, match=r"^_UnrebuildableError: 5 and 2$"):
        map_forked(fail, [5, 6], 2)


def test_a_child_that_dies_has_its_item_done_here() -> None:
    parent = os.getpid()

    def die_in_a_child(x: int) -> tuple[int, int]:
        if os.getpid() != parent and x == 2:
            os._exit(3)
        return os.getpid(), x

    out = map_forked(die_in_a_child, [1, 2, 3], 2)
    assert [x for _pid, x in out] == [1, 2, 3]
    assert out[1][0] == parent  # done here
    assert parent not in (out[0][0], out[2][0])


def test_a_child_works_on_one_thread_and_one_process_or_item_stays_here() -> None:
    assert map_forked(lambda _x: threads_here(), [0, 1], 2) == [1, 1]
    here = os.getpid()
    assert map_forked(lambda _x: os.getpid(), [0, 1], 1) == [here, here]
    assert map_forked(lambda _x: os.getpid(), [0], 4) == [here]


def test_no_child_is_left_running_when_the_parent_stops(tmp_path: Path) -> None:
    pids = tmp_path / "pids"

    def slow(x: int) -> int:
        with pids.open("a") as f:
            f.write(f"{os.getpid()}\n")
        time.sleep(60)
        return x

    def interrupt() -> None:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and (not pids.exists() or len(pids.read_text().split()) < 2):
            time.sleep(0.02)
        os.kill(os.getpid(), 2)  # SIGINT: Ctrl-C

    threading.Thread(target=interrupt, daemon=True).start()
    with pytest.raises(KeyboardInterrupt):
        map_forked(slow, [0, 1], 2)
    for pid in map(int, pids.read_text().split()):
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)  # killed and reaped


def test_a_child_s_warnings_are_shown_here() -> None:
    import warnings

    def warn(x: int) -> int:
        warnings.warn(f"item {x} looks odd", UserWarning, stacklevel=1)
        return x

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert map_forked(warn, [3, 4], 2) == [3, 4]
    assert sorted(str(w.message) for w in caught) == ["item 3 looks odd", "item 4 looks odd"]


def test_an_item_no_child_could_be_forked_for_is_done_here(monkeypatch: pytest.MonkeyPatch) -> None:
    def no_fork() -> int:
        raise BlockingIOError(11, "Resource temporarily unavailable")

    monkeypatch.setattr(os, "fork", no_fork)
    here = os.getpid()
    before = len(os.listdir("/proc/self/fd"))
    assert map_forked(lambda x: (os.getpid(), x), [1, 2, 3], 2) == [(here, 1), (here, 2), (here, 3)]
    assert len(os.listdir("/proc/self/fd")) == before  # no pipe left open


def test_a_bug_in_a_child_says_where_it_happened_there() -> None:
    def broken(x: int) -> int:
        return [x][x]  # IndexError for 1

    with pytest.raises(IndexError) as raised:
        map_forked(broken, [0, 1], 2)
    (note,) = raised.value.__notes__
    assert "in broken" in note
    assert "return [x][x]" in note
    assert note.endswith("IndexError: list index out of range")


def test_a_user_s_mistake_in_a_child_stays_one_line() -> None:
    def fail(x: int) -> int:
        raise AdapterError("/logs/run.mcap", "cannot decode its images")

    with pytest.raises(AdapterError) as raised:
        map_forked(fail, [0, 1], 2)
    assert not getattr(raised.value, "__notes__", None)
