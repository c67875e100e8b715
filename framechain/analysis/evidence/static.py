"""Static targets: every label is its own static object, its spread measured over short windows.

On a real log the strongest evidence is often a set of static targets (every AprilTag of a
house): seen from a moving robot, each must land on one world point. Three things make that
usable on real logs:

- each label (``ObservationTable.label``: a tag id; an empty label is one object) is its own
  object, so the spread is measured against the centre of *its* points, not of all of them;
- odometry drifts over minutes, so each object is fitted per time window (default
  :data:`DEFAULT_WINDOW_S`) as a point that may creep linearly in time: a slow drift then moves
  the fitted point, not the residuals, and does not pose as a fault;
- without depth (no depth in the detections, no depth frames: a tag centre with no size) the
  viewing rays of one object must meet in one point: :class:`RayObjective` measures how far each
  ray passes from the least-squares intersection of its group's rays (closed form, vectorised).

Objectives return residuals (N, 3) in metres; observations not used (a window with too few
points, a label seen from one viewpoint) get NaN and take no part in the fit.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
import numpy.typing as npt

from framechain.analysis.model.chain import ChainInputs, Perturbation, evaluate, hop1, hop2, hop3
from framechain.arrays import BoolArray, FloatArray, IntArray, StrArray
from framechain.errors import FramechainError
from framechain.timeline import Timeline, normalize_frame

#: Window over which one static object is fitted (s). Each object may creep linearly in time
#: within its window (odometry drift); what is left is the drift's curvature. Visual-inertial and
#: wheel odometry drift by about 0.5-2 % of the distance travelled; a bad case, 2 cm/s turning by
#: 0.05 rad/s, leaves at most 2 mm over 5 s once the linear creep is fitted (8 mm over 10 s, which
#: posed as a sub-millimetre latency in tests), while 5 s at 5-30 Hz still holds 25-150 views of a
#: tag and enough change of speed and viewpoint to show a 10 ms latency or a mount rotation.
#: Shorten it for fast-turning drift, lengthen it for slow, smooth rigs.
DEFAULT_WINDOW_S = 5.0
#: A (label, window) object seen fewer times than this is not used (its centre means nothing).
MIN_POINTS = 3
#: Rays of one bearing-only object must span at least this angle to meet in a point (degrees).
MIN_PARALLAX_DEG = 2.0
#: A bearing-only object needs more rays than its fit has unknowns (a point and a creep: 6, each
#: ray constraining 2): with fewer it fits any rays, and a small change throws it behind the camera.
MIN_RAYS = 6
#: Ridge on a bearing-only object's creep, relative to its mean curvature: creep along the viewing
#: direction (seen as a change of parallax only) stays near zero unless the rays clearly show it.
CREEP_RIDGE = 0.01
#: A latency margin that leaves fewer than this share of the observations is not applied.
MIN_KEPT_SHARE = 0.5


class StaticTargetError(FramechainError):
    """No static object was seen often enough to measure a spread (attribute reports it as one line)."""


class ResidualWeighting(Protocol):
    """A whitening of world residuals (see ``attribute._RayWeighting``)."""

    def apply(self, residual: FloatArray) -> FloatArray: ...

    def take(self, index: IntArray) -> ResidualWeighting: ...


@dataclass(frozen=True)
class StaticGroups:
    """Which static object, a (label, time window) pair, each observation belongs to."""

    group: IntArray  # (N,) object index, -1: the observation is not used
    tau_s: FloatArray  # (N,) time from the object's mean stamp (s), the drift term's regressor
    labels: tuple[str, ...]  # label of each object

    @property
    def n_groups(self) -> int:
        return len(self.labels)

    @property
    def used(self) -> BoolArray:
        out: BoolArray = self.group >= 0
        return out

    def take(self, index: IntArray) -> StaticGroups:
        return replace(self, group=self.group[index], tau_s=self.tau_s[index])

    def keep(self, mask: BoolArray) -> StaticGroups:
        """Only the observations in ``mask`` used; objects left with too few points dropped."""
        group = np.where(mask, self.group, -1)
        return _renumber(group, self.tau_s, self.labels)


def static_groups(
    labels: StrArray,
    stamp_ns: IntArray,
    *,
    window_s: float = DEFAULT_WINDOW_S,
    min_points: int = MIN_POINTS,
    usable: BoolArray | None = None,
) -> StaticGroups:
    """Group observations into (label, window) objects; windows are fixed bins from the first stamp."""
    n = stamp_ns.shape[0]
    if n == 0:
        return StaticGroups(np.zeros(0, dtype=np.int64), np.zeros(0), ())
    t_s = (stamp_ns - stamp_ns.min()) * 1e-9
    window = np.floor(t_s / window_s).astype(np.int64)
    n_windows = int(window.max()) + 1
    names, code = np.unique(np.asarray(labels, dtype=str), return_inverse=True)
    keys, group = np.unique(code.astype(np.int64) * n_windows + window, return_inverse=True)
    group = group.astype(np.int64)
    if usable is not None:
        group = np.where(usable, group, -1)
    group_labels = tuple(str(names[k // n_windows]) for k in keys)
    return _renumber(group, t_s, group_labels, min_points=min_points, centre=True)


def _renumber(
    group: IntArray, t_s: FloatArray, labels: tuple[str, ...], *, min_points: int = MIN_POINTS,
    centre: bool = False,
) -> StaticGroups:
    """Drop objects with fewer than ``min_points`` members, number the rest 0..G-1, centre their times."""
    size = max(len(labels), 1)
    counts = np.bincount(group[group >= 0], minlength=size)
    alive = counts >= min_points
    new_index = np.cumsum(alive) - 1
    out = np.where((group >= 0) & alive[np.maximum(group, 0)], new_index[np.maximum(group, 0)], -1).astype(np.int64)
    kept_labels = tuple(label for label, ok in zip(labels, alive[: len(labels)], strict=True) if ok)
    tau = t_s
    if centre and out.size:
        g = np.maximum(out, 0)
        n_groups = max(len(kept_labels), 1)
        w = (out >= 0).astype(float)
        cnt = np.maximum(np.bincount(g, w, minlength=n_groups), 1.0)
        mean_t = np.bincount(g, w * t_s, minlength=n_groups) / cnt
        tau = np.where(out >= 0, t_s - mean_t[g], 0.0)
    return StaticGroups(out, tau, kept_labels)


# -- objects with depth: the spread of their world points -----------------------------------
def fit_static_points(values: FloatArray, groups: StaticGroups, *, detrend: bool = True) -> FloatArray:
    """Each object's fitted position at each of its observations: its mean (plus a linear drift in
    time when ``detrend``), by least squares over its finite points; NaN for unused observations."""
    g = np.maximum(groups.group, 0)
    n_groups = max(groups.n_groups, 1)
    finite = np.isfinite(values).all(axis=1) & groups.used
    w = finite.astype(float)
    v = np.where(finite[:, None], values, 0.0)
    count = np.bincount(g, w, minlength=n_groups)
    safe = np.maximum(count, 1.0)
    mean_tau = np.bincount(g, w * groups.tau_s, minlength=n_groups) / safe
    tc = groups.tau_s - mean_tau[g]
    mean_v = np.stack([np.bincount(g, w * v[:, k], minlength=n_groups) for k in range(3)], axis=1) / safe[:, None]
    fitted = mean_v[g]
    if detrend:
        stt = np.bincount(g, w * tc * tc, minlength=n_groups)
        svt = np.stack([np.bincount(g, w * tc * v[:, k], minlength=n_groups) for k in range(3)], axis=1)
        slope = np.divide(svt, stt[:, None], out=np.zeros(svt.shape), where=stt[:, None] > 1e-12)
        fitted = fitted + slope[g] * tc[:, None]
    out: FloatArray = np.where((groups.used & (count[g] > 0))[:, None], fitted, np.nan)
    return out


def _median_range(p_cam: FloatArray) -> float:
    d = np.linalg.norm(p_cam, axis=1)
    d = d[np.isfinite(d)]
    return float(np.median(d)) if d.size else 0.0


@dataclass(frozen=True)
class WindowedSpreadObjective:
    """Residual of each world point from its own object's fitted position (label and window).

    As for one static target, the spread is measured relative to the points' range from the camera
    (rescaled to metres at the recorded range ``range_m``): shrinking every depth towards the camera
    shrinks any spread, and without that normalisation the target "collapses" for a depth or focal
    scale that explains nothing.
    """

    groups: StaticGroups
    range_m: float = 1.0
    detrend: bool = True
    weighting: ResidualWeighting | None = None

    def __call__(self, inputs: ChainInputs, pert: Perturbation) -> FloatArray:
        p_cam, _, p = evaluate(inputs, pert)
        out: FloatArray = (p - fit_static_points(p, self.groups, detrend=self.detrend))
        out = out * (self.range_m / max(_median_range(p_cam[self.groups.used]), 1e-9))
        return out if self.weighting is None else self.weighting.apply(out)

    def points(self, inputs: ChainInputs, pert: Perturbation) -> FloatArray:
        """The fitted static point of each observation (the evidence it is measured against)."""
        return fit_static_points(evaluate(inputs, pert)[2], self.groups, detrend=self.detrend)

    def take(self, index: IntArray) -> WindowedSpreadObjective:
        return replace(self, groups=self.groups.take(index),
                       weighting=None if self.weighting is None else self.weighting.take(index))


# -- bearing-only objects: rays that must meet ------------------------------------------------
def world_rays(inputs: ChainInputs, pert: Perturbation) -> tuple[FloatArray, FloatArray]:
    """Camera centres (N, 3) and unit viewing directions (N, 3) in the world under ``pert``.

    The depth (and any depth factor) does not change a ray's direction; NaN where a pose is missing.
    """
    p_cam = hop1(inputs, pert)
    p_world, ok = hop3(inputs, pert, hop2(inputs, pert, p_cam))
    origin, _ = hop3(inputs, pert, hop2(inputs, pert, np.zeros_like(p_cam)))
    direction = p_world - origin
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    origin[~ok] = np.nan
    direction[~ok] = np.nan
    return origin, direction


def intersect_rays(
    origin: FloatArray, direction: FloatArray, groups: StaticGroups, *, detrend: bool = True
) -> FloatArray:
    """Each object's least-squares ray intersection at each of its observations (NaN: unused).

    Minimises the squared perpendicular distances ``sum |(I - d d^T)(p_i - o_i)|^2`` with
    ``p_i = a + b tau_i`` (``b = 0`` without ``detrend``): the normal equations are 6x6 (3x3) per
    object, accumulated with bincount and solved batched.
    """
    if origin.shape[0] == 0:
        return np.zeros((0, 3))
    n_groups = max(groups.n_groups, 1)
    g = np.maximum(groups.group, 0)
    finite = np.isfinite(origin).all(axis=1) & np.isfinite(direction).all(axis=1) & groups.used
    w = finite.astype(float)
    d = np.where(finite[:, None], direction, 0.0)
    o = np.where(finite[:, None], origin, 0.0)
    m = np.eye(3)[None] - d[:, :, None] * d[:, None, :]  # (N, 3, 3) projectors across each ray
    mo = np.einsum("nij,nj->ni", m, o)
    tau = groups.tau_s
    dim = 6 if detrend else 3

    def acc(values: npt.NDArray[np.float64]) -> FloatArray:
        flat = values.reshape(values.shape[0], -1)
        out = np.stack([np.bincount(g, w * flat[:, k], minlength=n_groups) for k in range(flat.shape[1])], axis=1)
        return out.reshape((n_groups, *values.shape[1:]))

    a = np.zeros((n_groups, dim, dim))
    rhs = np.zeros((n_groups, dim))
    a[:, :3, :3] = acc(m)
    rhs[:, :3] = acc(mo)
    if detrend:
        a[:, :3, 3:] = acc(tau[:, None, None] * m)
        a[:, 3:, :3] = a[:, :3, 3:]
        a[:, 3:, 3:] = acc(tau[:, None, None] ** 2 * m)
        rhs[:, 3:] = acc(tau[:, None] * mo)
        creep_scale = np.trace(a[:, 3:, 3:], axis1=1, axis2=2) / 3.0
        a[:, 3:, 3:] += CREEP_RIDGE * creep_scale[:, None, None] * np.eye(3)[None]
    # A tiny ridge keeps degenerate objects (all rays parallel) solvable; usable ones are not moved.
    scale = np.maximum(np.trace(a, axis1=1, axis2=2) / dim, 1e-12)
    a += 1e-9 * scale[:, None, None] * np.eye(dim)[None]
    x = np.linalg.solve(a, rhs[:, :, None])[:, :, 0]
    points = x[g, :3]
    if detrend:
        points = points + x[g, 3:] * tau[:, None]
    count = np.bincount(g, w, minlength=n_groups)
    out: FloatArray = np.where((groups.used & (count[g] > 0))[:, None], points, np.nan)
    return out


def ray_residuals(origin: FloatArray, direction: FloatArray, points: FloatArray, range_m: float) -> FloatArray:
    """How far each point lies from its ray (a half-line: a point behind the camera is off by its
    whole distance), as an angle expressed in metres at ``range_m``: (N, 3) vectors."""
    v = points - origin
    along = np.einsum("ij,ij->i", v, direction)
    across = v - np.maximum(along, 0.0)[:, None] * direction
    dist = np.linalg.norm(v, axis=1, keepdims=True)
    out: FloatArray = across / np.maximum(dist, 1e-12) * range_m
    return out


@dataclass(frozen=True)
class RayObjective:
    """Bearing-only static objects: the rays of one object must meet in one point.

    Residuals are the perpendicular offsets of each ray from its object's intersection, as angles
    scaled to metres at the range ``range_m`` (so that no perturbation wins by pushing the
    intersection far away). Latency, a mount rotation, axis flips and intrinsics show in rays; a
    depth scale does not. Every chain is measured against its own intersections, as points with depth
    are against their own centre: a fault that moves every object together (a constant mount tilt)
    leaves the rays meeting and is no spread.
    """

    groups: StaticGroups
    range_m: float = 1.0
    detrend: bool = True

    def __call__(self, inputs: ChainInputs, pert: Perturbation) -> FloatArray:
        origin, direction = world_rays(inputs, pert)
        points = intersect_rays(origin, direction, self.groups, detrend=self.detrend)
        return ray_residuals(origin, direction, points, self.range_m)

    def points(self, inputs: ChainInputs, pert: Perturbation) -> FloatArray:
        origin, direction = world_rays(inputs, pert)
        return intersect_rays(origin, direction, self.groups, detrend=self.detrend)

    def take(self, index: IntArray) -> RayObjective:
        return replace(self, groups=self.groups.take(index))

    def at_range_of(self, inputs: ChainInputs, pert: Perturbation) -> RayObjective:
        """Errors in metres at the range where the rays of the chain corrected by ``pert`` meet (a
        faulty chain meets its rays at a wrong range); one range for every chain compared."""
        origin, direction = world_rays(inputs, pert)
        return replace(self, range_m=_intersection_range(origin, direction, self.groups, self.detrend, self.range_m))


def _intersection_range(
    origin: FloatArray, direction: FloatArray, groups: StaticGroups, detrend: bool, default: float
) -> float:
    """Median distance from the cameras to their objects' ray intersections (``default`` if none)."""
    points = intersect_rays(origin, direction, groups, detrend=detrend)
    ranges = np.linalg.norm(points - origin, axis=1)
    ranges = ranges[np.isfinite(ranges)]
    return float(np.median(ranges)) if ranges.size else default


def ray_objective(inputs: ChainInputs, groups: StaticGroups, *, detrend: bool = True) -> RayObjective:
    """A :class:`RayObjective` over the objects whose rays span :data:`MIN_PARALLAX_DEG` (the others
    cannot be triangulated), its range the median distance of the recorded intersections."""
    origin, direction = world_rays(inputs, Perturbation())
    n_groups = max(groups.n_groups, 1)
    g = np.maximum(groups.group, 0)
    finite = np.isfinite(direction).all(axis=1) & groups.used
    w = finite.astype(float)
    d = np.where(finite[:, None], direction, 0.0)
    outer = d[:, :, None] * d[:, None, :]
    count = np.maximum(np.bincount(g, w, minlength=n_groups), 1.0)
    mean_outer = np.stack(
        [np.bincount(g, w * outer[:, i, j], minlength=n_groups) for i in range(3) for j in range(3)], axis=1
    ).reshape(n_groups, 3, 3) / count[:, None, None]
    # The spread of directions across the mean one: the smallest non-trivial eigenvalue of
    # mean(I - d d^T) is about sin^2 of the angle the rays span.
    spread = np.linalg.eigvalsh(np.eye(3)[None] - mean_outer)[:, 0]
    wide = spread >= np.sin(np.deg2rad(MIN_PARALLAX_DEG)) ** 2 / 4.0
    groups = groups.keep(groups.used & wide[g] & (count[g] >= MIN_RAYS))
    return RayObjective(groups, _intersection_range(origin, direction, groups, detrend, 1.0), detrend)


# -- what the log holds -----------------------------------------------------------------------
def chain_observations(timeline: Timeline, camera: str) -> BoolArray:
    """Observations the replay gives to ``camera`` (all but those of another camera with CameraInfo)."""
    obs = timeline.observations
    others = sorted(set(np.unique(timeline.cameras.frame).tolist()) - {normalize_frame(camera)})
    out: BoolArray = ~np.isin(obs.camera_frame, others) if others else np.ones(len(obs), dtype=bool)
    return out


def is_bearing_only(timeline: Timeline, camera: str) -> bool:
    """Whether the chain has no depth source at all: no depth in its detections, no depth frames."""
    mine = chain_observations(timeline, camera)
    if not mine.any() or np.isfinite(timeline.observations.depth_m[mine]).any():
        return False
    return not bool((timeline.depth_frames.frame == normalize_frame(camera)).any())


def with_unit_depth(timeline: Timeline, camera: str) -> tuple[Timeline, int]:
    """The timeline with a depth of 1 m on the chain's depthless observations (replayed as rays),
    and how many were given one."""
    obs = timeline.observations
    fill = chain_observations(timeline, camera) & np.isnan(obs.depth_m)
    depth = np.where(fill, 1.0, obs.depth_m)
    return timeline.replace(observations=replace(obs, depth_m=depth)), int(fill.sum())


def latency_margin(inputs: ChainInputs, bound_s: float) -> BoolArray:
    """Observations whose poses exist ``bound_s`` before and after their stamp (so that every time
    offset the latency search tries is evaluated on the same observations)."""
    shift = round(bound_s * 1e9)
    ok = np.ones(len(inputs), dtype=bool)
    pairs = [(inputs.frames.world, inputs.frames.body)]
    if inputs.camera_is_dynamic:
        pairs.append((inputs.frames.body, inputs.frames.camera))
    for target, source in pairs:
        for sign in (-1, 1):
            ok &= inputs.buffer.lookup(target, source, inputs.stamp_ns + sign * shift).ok
    return ok


StaticObjective = WindowedSpreadObjective | RayObjective


def static_objective(
    inputs: ChainInputs,
    labels: StrArray,
    *,
    window_s: float | None = None,
    bearing_only: bool = False,
    latency_bound_s: float = 0.0,
) -> tuple[StaticObjective, list[str]]:
    """The objective of a static-target log (one object per label and window) and notes on what
    it used. ``labels`` are the replayed observations' labels (the rows of ``inputs``)."""
    window = DEFAULT_WINDOW_S if window_s is None else window_s
    notes: list[str] = []
    usable = np.ones(len(inputs), dtype=bool)
    if latency_bound_s > 0:
        inside = latency_margin(inputs, latency_bound_s)
        if inside.mean() >= MIN_KEPT_SHARE and not inside.all():
            usable = inside
            notes.append(f"static targets: {int((~inside).sum())} observations within {latency_bound_s:g} s of the "
                         "ends of the poses not used (every time offset searched is measured on the same points)")
    groups = static_groups(labels, inputs.stamp_ns, window_s=window, usable=usable)
    if groups.n_groups == 0:
        raise StaticTargetError(_too_few_sightings(labels, inputs.stamp_ns, window, usable, MIN_POINTS, ""))
    objective: StaticObjective
    if bearing_only:
        objective = ray_objective(inputs, groups)
        groups = objective.groups
        seen = f"objects seen at least {MIN_RAYS} times in a window, from viewpoints {MIN_PARALLAX_DEG:g} deg apart"
        if groups.n_groups == 0:
            raise StaticTargetError(_too_few_sightings(
                labels, inputs.stamp_ns, window, usable, MIN_RAYS,
                f" from viewpoints at least {MIN_PARALLAX_DEG:g} deg apart (bearing only: declare the tag sizes "
                "to measure each sighting's depth)"))
    else:
        p_cam = evaluate(inputs, Perturbation())[0]
        objective = WindowedSpreadObjective(groups, _median_range(p_cam[groups.used]))
        seen = f"objects seen at least {MIN_POINTS} times in a window"
    n_labels = len(set(groups.labels))
    notes.append(
        f"static targets: {n_labels} label{'s' if n_labels != 1 else ''} in {groups.n_groups} windows of "
        f"{window:g} s; {int(groups.used.sum())} of {len(inputs)} replayed observations used ({seen}), each "
        "measured against its own object's position"
    )
    return objective, notes


def _too_few_sightings(
    labels: StrArray, stamp_ns: IntArray, window_s: float, usable: BoolArray, needed: int, how: str
) -> str:
    """One line on why no static object can be measured: how many labels, the most sightings of one
    label in one window, and what to change."""
    every = static_groups(labels, stamp_ns, window_s=window_s, min_points=1, usable=usable)
    counts = np.bincount(every.group[every.used], minlength=max(every.n_groups, 1))
    n_labels = len(set(every.labels))
    most = int(counts.max()) if every.n_groups else 0
    return (
        f"static target: no object seen at least {needed} times in one {window_s:g} s window{how} "
        f"({n_labels} label{'s' if n_labels != 1 else ''} among {int(usable.sum())} observations, at most {most} "
        f"sighting{'s' if most != 1 else ''} of one label in a window); "
        f"{_what_can_help(labels, stamp_ns, usable, needed)}"
    )


def _what_can_help(labels: StrArray, stamp_ns: IntArray, usable: BoolArray, needed: int) -> str:
    """The change that can give an object enough sightings: a longer window only when the whole log holds them."""
    images = np.unique(stamp_ns[usable]).size
    if images <= 1:
        return ("the log holds one image, where each object is seen once: a longer evidence.static_window_s cannot "
                "add sightings; record the static objects in more images, from other viewpoints (or give "
                "evidence.reference_point)")
    names, per_label = np.unique(labels[usable], return_counts=True)
    whole = int(per_label.max()) if per_label.size else 0
    if whole < needed:
        return (f"the whole log holds at most {whole} sighting{'s' if whole != 1 else ''} of one label, so a longer "
                "evidence.static_window_s cannot help: record more images of each static object")
    best = str(names[np.argmax(per_label)])
    span_s = (int(stamp_ns[usable].max()) - int(stamp_ns[usable].min())) * 1e-9
    return (f"lengthen evidence.static_window_s (the whole log, {span_s:.3g} s, holds {whole} sightings of label "
            f"{best}) or record more observations of each static object")
