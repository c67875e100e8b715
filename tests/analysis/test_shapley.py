"""Shapley values of small games against hand-worked numbers."""

from __future__ import annotations

import pytest

from framechain.analysis.fit.shapley import shapley_values


def test_shapley_values_split_what_a_coalition_is_worth_and_add_up_to_the_whole() -> None:
    # Glove game: player 0 holds a left glove, 1 and 2 a right one; a pair is worth 1.
    def pairs(coalition: frozenset[int]) -> float:
        return float(min(int(0 in coalition), len(coalition & {1, 2})))

    values = shapley_values(3, pairs)
    assert values == pytest.approx([2 / 3, 1 / 6, 1 / 6])
    assert sum(values) == pytest.approx(pairs(frozenset({0, 1, 2})))


def test_shapley_values_ask_each_coalition_once() -> None:
    asked: list[frozenset[int]] = []

    def additive(coalition: frozenset[int]) -> float:
        asked.append(coalition)
        return sum(10.0**k for k in coalition)

    assert shapley_values(3, additive) == pytest.approx([1.0, 10.0, 100.0])
    assert len(asked) == len(set(asked)) == 8
    assert shapley_values(0, additive) == []
