"""Chaining the hops of a path into ``T_target_source``: a plan of steps (static runs folded into one
constant) applied chunk by chunk in place (:func:`compose_chunk`, the lookup hot path), or on whole
per-hop samples (:func:`compose_hops`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from framechain.arrays import FloatArray
from framechain.geometry.rotations import IDENTITY, Quat4, Vec3, compose, invert, quat_multiply_into, quat_rotate_into
from framechain.replay.interpolation import HopViews, Workspace
from framechain.replay.samples import HopSamples

_IN_OUTPUT = 2
_IDENTITY_STEP: tuple[Vec3, Quat4] = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


@dataclass(frozen=True)
class Step:
    """One step of a composition plan: a dynamic hop (by index), or a constant (folded static hops)."""

    dynamic: int = -1
    inverse: bool = False
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    @classmethod
    def constant(cls, t: FloatArray, q: FloatArray) -> Step:
        tr = t.reshape(3)
        qu = q.reshape(4)
        return cls(translation=(float(tr[0]), float(tr[1]), float(tr[2])),
                   quat=(float(qu[0]), float(qu[1]), float(qu[2]), float(qu[3])))


def compose_chunk(
    plan: list[Step], hops: list[HopViews], out_t: FloatArray, out_q: FloatArray, ws: Workspace
) -> None:
    """``T_target_source`` for one chunk: the plan's steps applied from the source, into ``out_t``/``out_q``.

    Walking from the source the running transform is ``T_current_source``; each step multiplies it
    on the left. Intermediate products alternate between two scratch pairs, so no product writes
    over its own inputs; the last one goes straight into the output rows.
    """
    scratch, delta, pairs = ws.composing()
    current: tuple[Vec3, Quat4] | None = None
    held = -1  # the pair holding ``current`` (-1: a hop's own rows or a constant; _IN_OUTPUT: the output)
    for i, step in enumerate(plan):
        last = i == len(plan) - 1
        dest = _IN_OUTPUT if last else (1 if held == 0 else 0)
        t_out, q_out = (out_t, out_q) if last else pairs[dest]
        if step.dynamic < 0:  # a constant (folded static hops) on the left
            if current is None:  # only constants so far (a plan never holds two in a row)
                current, held = (step.translation, step.quat), -1
                continue
            quat_rotate_into(step.quat, current[0], t_out, scratch)
            for k in range(3):
                t_out[k] += step.translation[k]
            quat_multiply_into(step.quat, current[1], q_out, scratch)
        else:
            hop = hops[step.dynamic]
            t_e: Vec3 = (hop.translation[0], hop.translation[1], hop.translation[2])
            q_e: Quat4 = (hop.quat[0], hop.quat[1], hop.quat[2], hop.quat[3])
            if current is None and not step.inverse:
                current, held = (t_e, q_e), -1  # read only: the hop's own rows
                continue
            t_x, q_x = current if current is not None else _IDENTITY_STEP
            if step.inverse:  # inv(E) X = (conj(q_E) (t_X - t_E), conj(q_E) q_X)
                for k in range(3):
                    np.subtract(t_x[k], t_e[k], out=delta[k])
                quat_rotate_into(q_e, (delta[0], delta[1], delta[2]), t_out, scratch, conjugate_q=True)
                quat_multiply_into(q_e, q_x, q_out, scratch, conjugate_a=True)
            else:  # E X = (q_E t_X + t_E, q_E q_X)
                quat_rotate_into(q_e, t_x, t_out, scratch)
                for k in range(3):
                    t_out[k] += t_e[k]
                quat_multiply_into(q_e, q_x, q_out, scratch)
        current, held = ((t_out[0], t_out[1], t_out[2]), (q_out[0], q_out[1], q_out[2], q_out[3])), dest
    if held != _IN_OUTPUT:  # the result is not in the output rows yet: a hop's rows, a constant, or nothing
        t_c, q_c = current if current is not None else _IDENTITY_STEP
        for k in range(3):
            out_t[k] = t_c[k]
        for k in range(4):
            out_q[k] = q_c[k]


def compose_hops(samples: tuple[HopSamples, ...], n: int) -> tuple[FloatArray, FloatArray]:
    """Chain the hops of a path into ``T_target_source``: translations (3, n), quaternions (4, n).

    Walking from the source, the running transform is ``T_current_source``. Runs of static hops
    are folded into one constant transform before they touch the arrays.
    """
    trans: FloatArray | None = None  # None while the running transform is still a constant
    quat: FloatArray | None = None
    const: tuple[FloatArray, FloatArray] | None = None  # folded static hops; None = identity
    for s in samples:
        if s.hop.is_static:
            t_edge, q_edge = s.translation_soa[:, :1], s.quat_soa[:, :1]
        else:
            t_edge, q_edge = s.translation_soa, s.quat_soa
        if s.hop.inverse:
            t_edge, q_edge = invert(t_edge, q_edge)
        if s.hop.is_static:
            const = (t_edge, q_edge) if const is None else compose(t_edge, q_edge, *const)
            continue
        t_step, q_step = (t_edge, q_edge) if const is None else compose(t_edge, q_edge, *const)
        if trans is None or quat is None:
            trans, quat = t_step, q_step
        else:
            trans, quat = compose(t_step, q_step, trans, quat)
        const = None
    if trans is None or quat is None:
        t_c, q_c = const if const is not None else (np.zeros((3, 1)), IDENTITY[:, None])
        return np.repeat(t_c, n, axis=1), np.repeat(q_c, n, axis=1)
    if const is None:
        return np.array(trans, copy=True), np.array(quat, copy=True)
    return compose(*const, trans, quat)
