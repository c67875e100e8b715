"""A fault hypothesis as a small model over the vectorised chain: parameters, bounds, and what it
does to the chain (a :class:`Perturbation`); the catalogue's models are in :mod:`faults`, the
frame swaps in :mod:`frame_swaps`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from framechain.analysis.model.chain import ChainInputs, Perturbation
from framechain.analysis.model.estimates import Estimate
from framechain.arrays import FloatArray
from framechain.catalogue import Fault, HopName

Mode = Literal["as_run", "correction"]

@dataclass(frozen=True)
class FaultModel:
    """One fault hypothesis: its parameters, bounds, and what it does to the chain."""

    name: str  # unique label, e.g. "axis_flip[0,1,2|+,-,+]"
    fault: Fault
    hop: HopName
    family: str
    apply: Callable[[Perturbation, FloatArray], Perturbation]
    estimate: Callable[[FloatArray, Mode, ChainInputs], Estimate]
    #: parameter start, bounds and scale; empty for a model with no parameters (a discrete choice)
    x0: tuple[float, ...] = ()
    lower: tuple[float, ...] = ()
    upper: tuple[float, ...] = ()
    x_scale: tuple[float, ...] = ()
    #: extra BIC penalty for a discrete choice among many variants (log of their number)
    choice_penalty: float = 0.0
    #: extra starting points for the local fit (multi-start)
    starts: tuple[tuple[float, ...], ...] = ()
    #: whether the bounds mark the plausible range (a fit ending on one explains nothing) rather
    #: than the limits of the parametrisation (a rotation vector's |component| <= pi)
    plausibility_bounds: bool = True
    #: the rig camera (its optical frame) whose chain the model changes (None: the chain as a whole)
    camera: str | None = None
    #: the fix of a fitted model, when the model words its own (a rig camera's mount in the chain's form)
    fix: Callable[[FloatArray, Mode, ChainInputs], str] | None = None
    #: whether fitted parameters stay within what the evidence can pin on this fault (then it is no finding,
    #: however well it fits); None: any fit that pays for itself is one
    tolerance: Callable[[FloatArray], bool] | None = None
    #: weight of a pull towards no fault (residual per parameter unit, added for the optimiser only, never to the
    #: BIC): a direction the evidence cannot see stays at no fault instead of drifting (a mount moved along the
    #: only axis the body turns about)
    ridge: float = 0.0

    @property
    def n_params(self) -> int:
        return len(self.x0)
