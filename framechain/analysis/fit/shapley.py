"""Shapley values: what each of a few players is worth to a game, its marginal worth averaged over every
coalition of the others. Attribution splits the error among the faults found this way (their shares add
up to what all of them explain), and a camera's motion its misfit among the corrections it proposes."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

__all__ = ["shapley_values"]


def shapley_values(players: int, worth: Callable[[frozenset[int]], float]) -> list[float]:
    """Each player's Shapley value (players ``0 .. players - 1``) of the game whose coalition ``s`` is worth
    ``worth(s)`` (asked once per coalition: ``2^players`` of them, cheap for a handful)."""
    cache: dict[frozenset[int], float] = {}

    def value(coalition: frozenset[int]) -> float:
        if coalition not in cache:
            cache[coalition] = worth(coalition)
        return cache[coalition]

    out = []
    for i in range(players):
        others = [j for j in range(players) if j != i]
        phi = 0.0
        for size in range(players):
            weight = math.factorial(size) * math.factorial(players - size - 1) / math.factorial(players)
            for subset in itertools.combinations(others, size):
                without = frozenset(subset)
                alone = value(without)
                phi += weight * (value(without | {i}) - alone)
        out.append(phi)
    return out
