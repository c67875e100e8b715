"""A camera's measured motion against forward kinematics: time offset, mount rotation, carrying link.

A camera on a link turns as its link turns. Between two frames stamped ``t0`` and ``t1`` the image
measures ``B = R_cam(t0)_cam(t1)`` (:class:`~framechain.timeline.EgoMotionTable`); forward kinematics
predicts the link's ``A = R_base_link(t0 + offset)^T R_base_link(t1 + offset)``, and with the mount
rotation ``X = R_link_cam``::

    B = X^T A X,   i.e.   rotvec(B) = X^T rotvec(A)

So for each trial ``offset_s`` the mount is a weighted Kabsch fit of the rotation axes (hand-eye
rotation), and the offset is the one that leaves the smallest misfit. Conventions as the fault
catalogue's latency: the pose that matches a frame stamped ``t`` is at ``t + offset_s``, so frames
late by ``d`` (showing the world ``d`` before their stamp) give ``offset_s = -d``.

A wrist camera over a table also translates, and near scenery moves with the translation: an
image-only rotation reads part of it as rotation (tens of percent at 0.3 m). So
:func:`fit_camera_motion` measures again with the translation direction forward kinematics
predicts (:func:`translation_prior`: the link's motion, the declared mount's position, the
current mount rotation and offset) and refits, a contraction towards the right values,
accelerated with Anderson mixing; three to five measurements usually settle it.

What each candidate link explains tells which link (which arm) the camera moves with. A link that
turns about one axis only leaves the mount's rotation about that axis unobservable; a camera that
does not turn (a fixed camera, a still arm) shows neither offset nor mount.

Intervals are 95% block bootstrap intervals over the frame pairs (Bayesian: each block of ``block_s``
weighed by an exponential draw),
the mount's and offset's jointly (on synthetic rotations they hold the truth in about 85% of
episodes: a little narrow). When the intrinsics are not known, the ratio of measured to
predicted rotation across the optical axis is the ratio of true to assumed focal length.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from framechain.analysis.egomotion.joint import Joint, Searched, finish_fit, search_offset
from framechain.analysis.egomotion.model import (
    EgoMotionFit,
    EgoMotionFitOptions,
    LinkFit,
    LinkMotion,
    Measure,
    MountError,
)
from framechain.analysis.egomotion.solve import (
    Observed,
    Orientations,
    Pairs,
    Solved,
    block_bootstrap,
    complete_mount,
    focal_scale,
    frame_pairs,
    information,
    interval,
    link_fit,
    link_rotvecs,
    mount_evidence,
    observed,
    offset_undetermined,
    solve,
    too_short,
)
from framechain.arrays import FloatArray, IntArray
from framechain.geometry.rotations import Inverse, angle_of, matrix_of, quat_of, rotate_by, rotvec_of
from framechain.timeline import EgoMotionTable, TranslationPrior

__all__ = ["SWUNG_SHARE", "RotationRates", "fit_camera_motion", "fit_link", "focal_hidden", "rotation_rates",
           "swung_share", "translation_prior"]

def fit_link(
    measured: EgoMotionTable, link: LinkMotion, options: EgoMotionFitOptions | None = None
) -> LinkFit | None:
    """The offset and mount that best explain the measured motion by ``link``'s; None with too few pairs."""
    opts = options or EgoMotionFitOptions()
    origin = int(link.stamps_ns[0])
    span = (0.0, (int(link.stamps_ns[-1]) - origin) * 1e-9)
    pairs = frame_pairs(measured, origin, span, opts.max_offset_s)
    if pairs.t0.size < opts.min_pairs:
        return None
    orientations = Orientations(link, origin)
    return link_fit(link.link, pairs, solve(orientations, pairs, opts), orientations)


def translation_prior(
    link: LinkMotion, q_link_cam: FloatArray, xyz_link_cam: FloatArray, offset_s: float
) -> TranslationPrior:
    """The camera's translation direction FK predicts between two frame stamps, in the earlier optical frame.

    The camera centre is ``p_link(t) + R_link(t) xyz_link_cam`` at ``t = stamp + offset_s``; rows
    outside the link's span (or without link positions) are NaN.
    """
    if link.xyz is None:
        raise ValueError(f"link {link.link!r}: no positions for a translation prior")
    origin = int(link.stamps_ns[0])
    orientations = Orientations(link, origin)
    times = orientations.times
    centres = np.asarray(link.xyz, dtype=float) + rotate_by(np.asarray(link.quat_xyzw, dtype=float),
                                                             np.asarray(xyz_link_cam, dtype=float))
    mount = np.asarray(q_link_cam, dtype=float)

    def prior(stamp0_ns: IntArray, stamp1_ns: IntArray) -> FloatArray:
        t0 = (np.asarray(stamp0_ns, dtype=np.int64) - origin) * 1e-9 + offset_s
        t1 = (np.asarray(stamp1_ns, dtype=np.int64) - origin) * 1e-9 + offset_s
        inside = (t0 >= times[0]) & (t1 <= times[-1])
        out = np.full((t0.size, 3), np.nan)
        if not inside.any():
            return out
        c0 = np.stack([np.interp(t0[inside], times, centres[:, i]) for i in range(3)], axis=1)
        c1 = np.stack([np.interp(t1[inside], times, centres[:, i]) for i in range(3)], axis=1)
        cam0 = (orientations.at(t0[inside]).T, mount)
        move = rotate_by(Inverse(cam0), c1 - c0)
        norm = np.linalg.norm(move, axis=1, keepdims=True)
        out[inside] = np.where(norm > 1e-9, move / np.maximum(norm, 1e-12), np.nan)
        return out

    return prior


@dataclass(frozen=True)
class RotationRates:
    """A camera's rotation between frame pairs, measured and as a link's forward kinematics predicts it.

    Rates (rad/s) are rotation vectors in the camera's optical frame over the pair's time; the
    prediction is the link's rotation between the pair's stamps shifted by ``offset_s``, carried into
    the camera by the mount (NaN outside the link's span). The measured rates are corrected for a focal
    scale (measured over true rotation across the optical axis).
    """

    stamp0_ns: IntArray
    stamp1_ns: IntArray
    measured: FloatArray  # (N, 3)
    predicted: FloatArray  # (N, 3)

    @property
    def residual(self) -> FloatArray:
        """``|measured - predicted|`` per pair (rad/s; NaN where nothing is predicted)."""
        out: FloatArray = np.linalg.norm(self.measured - self.predicted, axis=1)
        return out


def rotation_rates(
    measured: EgoMotionTable, link: LinkMotion, q_link_cam: FloatArray, offset_s: float, *, focal_scale: float = 1.0
) -> RotationRates:
    """The measured pairs of ``measured`` against ``link`` carrying the camera by the mount ``q_link_cam``."""
    origin = int(link.stamps_ns[0])
    orientations = Orientations(link, origin)
    t0: FloatArray = ((measured.stamp0_ns - origin) * 1e-9).astype(np.float64)
    t1: FloatArray = ((measured.stamp1_ns - origin) * 1e-9).astype(np.float64)
    dt = t1 - t0
    camera = rotvec_of(measured.quat_xyzw) if len(measured) else np.zeros((0, 3))
    camera = camera * np.array([1.0 / focal_scale, 1.0 / focal_scale, 1.0])
    pairs = Pairs(t0=t0, t1=t1, rotvec=camera, weight=np.ones(t0.size))
    link_rv = link_rotvecs(orientations, pairs, np.array([offset_s]))[0]
    inside = (t0 + offset_s >= orientations.times[0]) & (t1 + offset_s <= orientations.times[-1])
    predicted = np.where(inside[:, None], link_rv @ matrix_of(np.asarray(q_link_cam, dtype=float)), np.nan)
    return RotationRates(stamp0_ns=measured.stamp0_ns, stamp1_ns=measured.stamp1_ns, measured=camera / dt[:, None],
                         predicted=predicted / dt[:, None])


def fit_camera_motion(
    measure: Measure,
    links: Sequence[LinkMotion],
    *,
    camera: str,
    declared_link: str,
    declared_q_link_cam: FloatArray,
    declared_xyz_link_cam: FloatArray | None = None,
    refinements: int = 5,
    options: EgoMotionFitOptions | None = None,
    measured: tuple[EgoMotionTable, list[LinkFit]] | None = None,
    mount_prior: FloatArray | None = None,
) -> EgoMotionFit:
    """Offset, mount and carrying link of a camera from its measured motion against the candidate links' FK.

    ``measure(prior)`` measures the camera's motion (:func:`framechain.vision.egomotion.
    measure_egomotion` with the camera's tracks). Rotation-only first, to see whether the camera
    turns at all and to rank every candidate link. The declared link, and the links that fit about as
    well as the best without moving rigidly with the declared one (at most :data:`_MAX_CANDIDATES`),
    are then each fitted with their own translation prior (:mod:`.joint`, from the declared mount
    and from their rotation-only mount, so a placeholder mount does no harm; one whose offset search and mount
    fixed point already misfit :data:`SEARCH_SCREEN` times a finished one's is not fitted further); the one
    whose own measurement fits best wins, the declared link kept when it fits within ``same_fit_ratio`` of it
    (near scenery moves with the camera's translation, which a rotation-only measurement reads as
    rotation, so only measurements made with each link's own prior are compared). ``measured``: ``measure(None)``
    and its :func:`rank_links`, when the caller has them already. ``mount_prior``: a mount measured otherwise (by
    :mod:`.position`, with the camera's translation): the search starts from it rather than the declared one, and
    a mount axis the link never turned about keeps it; the mount error is still against the declared mount.
    """
    opts = options or EgoMotionFitOptions()
    table = measure(None) if measured is None else measured[0]
    notes: list[str] = []
    turning = _rms_deg(rotvec_of(table.quat_xyzw)) if len(table) else 0.0
    if still := _still(camera, len(table), turning, opts):
        return _unobservable(camera, declared_link, turning, [still])
    ranked = rank_links(table, links, opts) if measured is None else measured[1]
    if not ranked:
        notes.append(f"camera {camera}: fewer than {opts.min_pairs} measured frame pairs lie the offset search window "
                     f"(+-{opts.max_offset_s:g} s, evidence.camera_offset_window_s) inside both ends of the links' "
                     "span")
        return _unobservable(camera, declared_link, turning, notes)
    prior = np.asarray(declared_q_link_cam if mount_prior is None else mount_prior, dtype=float)
    declared = _Start(prior, 0.0, np.zeros(3) if declared_xyz_link_cam is None else np.asarray(declared_xyz_link_cam))
    by_name = {link.link: link for link in links}
    tried = _refined(measure, [by_name[name] for name in _to_refine(ranked, declared_link, by_name, opts)], declared,
                     (table, ranked), refinements, opts)
    misfit = {name: item[1].residual_deg for name, item in tried.items()}
    best = min(misfit, key=lambda name: misfit[name])
    if declared_link in misfit and misfit[declared_link] <= opts.same_fit_ratio * misfit[best]:
        best = declared_link
    table, fit, joint = tried[best]
    # Only the winner's measurement is ranked: with its own prior it differs from the rotation-only one.
    ranked = ranked if joint is None else rank_links(table, links, opts)
    link = by_name[fit.link]
    similar = _similar(ranked, next((f for f in ranked if f.link == fit.link), fit), opts)
    return _final(table, link, fit, ranked, similar, declared_link,
                  (np.asarray(declared_q_link_cam, dtype=float), None if mount_prior is None else prior), camera,
                  turning, notes, opts, joint)


def _still(camera: str, pairs: int, turning: float, opts: EgoMotionFitOptions) -> str:
    """Why the camera's measurement shows no motion ("" when it shows some): no frame pair measured, or too little
    turn in them."""
    if not pairs:
        return (f"camera {camera}: none of its frame pairs could be measured (its frames repeat one another, as a "
                "still arm's or a fixed camera's do, or too few features were tracked into both frames of a pair, or "
                "too few agree on one motion): its time offset, mount and link are not observable from its images")
    if turning < opts.min_rotation_deg:
        return (f"camera {camera} does not turn ({turning:.3f} deg RMS per frame pair): a fixed camera or a still "
                "arm; its time offset, mount and link are not observable from its images")
    return ""


def _to_refine(ranked: list[LinkFit], declared_link: str, by_name: dict[str, LinkMotion],
               opts: EgoMotionFitOptions) -> list[str]:
    """The declared link (when ranked), and the links ranked above it within ``same_fit_ratio`` of the best that do
    not move rigidly with a link already chosen (at most :data:`_MAX_CANDIDATES` in all)."""
    declared = next((f for f in ranked if f.link == declared_link), None)
    out = [declared_link] if declared is not None else []
    for f in ranked:
        if (len(out) >= _MAX_CANDIDATES or f.residual_deg > opts.same_fit_ratio * ranked[0].residual_deg
                or (declared is not None and f.residual_deg >= declared.residual_deg)):
            break
        if f.link not in out and not any(_rigid(by_name[f.link], by_name[name]) for name in out):
            out.append(f.link)
    return out or [ranked[0].link]


def _rigid(a: LinkMotion, b: LinkMotion) -> bool:
    """``a`` and ``b`` turn together: their relative rotation changes by under 0.5 deg over the recording."""
    if a.stamps_ns.size != b.stamps_ns.size or not np.array_equal(a.stamps_ns, b.stamps_ns):
        return False
    relative = (Inverse(a.quat_xyzw), b.quat_xyzw)
    first = (Inverse(a.quat_xyzw[0]), b.quat_xyzw[0])
    spread = angle_of((Inverse(first), relative))
    return bool(np.rad2deg(spread.max()) < 0.5)


#: At most this many candidate links are fitted with their own translation prior.
_MAX_CANDIDATES = 3


@dataclass(frozen=True)
class _Start:
    """Where a refinement starts: mount rotation (xyzw), offset (s), the camera's position on the link (m)."""

    q_link_cam: FloatArray
    offset_s: float
    xyz: FloatArray


#: A candidate whose misfit after its offset search and mount fixed point is this many times that of a candidate
#: finished already is not fitted further. On generated single- and two-arm episodes with every link fitted through,
#: the rest of a fit lowered a misfit by a factor of 2.05 at most (the right link, video 0.3 s late and mount 30 deg
#: off; 1.0 to 1.1 for the others), and the declared link is kept within ``same_fit_ratio`` (1.25) of the best: 4
#: leaves a margin of about 1.56 over what was seen (an observed bound, not a proven one). The links that lose were 5
#: to 50 times the right one there.
SEARCH_SCREEN = 4.0


def _refined(
    measure: Measure, links: Sequence[LinkMotion], declared: _Start, first: tuple[EgoMotionTable, list[LinkFit]],
    refinements: int, opts: EgoMotionFitOptions,
) -> dict[str, tuple[EgoMotionTable, LinkFit, Joint | None]]:
    """Each link's fit on measurements made with its own translation prior (:mod:`.joint`: the offset used for the
    prior and for the comparison at once), from the declared mount and from its rotation-only one. The links are
    finished best searched first; one whose search misfits :data:`SEARCH_SCREEN` times a finished one's is left out.

    Without link positions (or refinements, or pairs) a link's rotation-only fit stands.
    """
    own = {f.link: f for f in first[1]}
    searched: dict[str, Searched | None] = {
        link.link: None if link.xyz is None or refinements <= 0 else search_offset(
            measure, link, translation_prior, [declared.q_link_cam, own[link.link].q_link_cam], declared.xyz,
            [declared.offset_s, own[link.link].offset_s], opts)
        for link in links}
    finished: dict[str, tuple[EgoMotionTable, LinkFit, Joint | None]] = {}
    least = np.inf  # the search misfit of the best link finished so far
    for link in sorted(links, key=lambda m: _searched_misfit(searched[m.link])):
        found = searched[link.link]
        if found is not None and found.misfit_deg > SEARCH_SCREEN * least:
            continue
        best = None if found is None else finish_fit(found)
        if found is None or best is None:
            finished[link.link] = (first[0], own[link.link], None)
            continue
        least = min(least, found.misfit_deg)
        orientations = Orientations(link, int(link.stamps_ns[0]))
        fit = replace(link_fit(link.link, best.pairs, best.solved, orientations), residual_deg=best.residual_deg)
        finished[link.link] = (best.table, fit, best)
    return {link.link: finished[link.link] for link in links if link.link in finished}  # in the candidates' order


def _searched_misfit(searched: Searched | None) -> float:
    return np.inf if searched is None else searched.misfit_deg


def rank_links(table: EgoMotionTable, links: Sequence[LinkMotion], opts: EgoMotionFitOptions) -> list[LinkFit]:
    """Every candidate's best fit to the measured motion, best first (offsets on a grid of 20 ms at least: a ranking
    needs no finer)."""
    coarse = opts.for_ranking()
    return sorted((f for f in (fit_link(table, link, coarse) for link in links) if f is not None),
                  key=lambda f: f.residual_deg)


def _similar(ranked: list[LinkFit], reference: LinkFit, opts: EgoMotionFitOptions) -> tuple[str, ...]:
    """The links that explain the motion about as well as ``reference`` (within ``same_fit_ratio``)."""
    best = min(reference.residual_deg, ranked[0].residual_deg)
    return tuple(f.link for f in ranked if f.residual_deg <= best * opts.same_fit_ratio)


def _rms_deg(rotvec: FloatArray) -> float:
    return float(np.rad2deg(np.sqrt((rotvec**2).sum(axis=1).mean()))) if rotvec.size else 0.0


def _unobservable(camera: str, declared_link: str, turning: float, notes: list[str]) -> EgoMotionFit:
    nan2 = (float("nan"), float("nan"))
    return EgoMotionFit(
        camera=camera, link="", declared_link=declared_link, alternatives=(), links=(), offset_s=float("nan"),
        offset_interval_s=nan2, q_link_cam=np.full(4, np.nan), mount_error=None, focal_scale=float("nan"),
        focal_scale_interval=nan2, camera_rotation_deg=turning, offset_observable=False, mount_observable=False,
        notes=tuple(notes),
    )


def _final(
    table: EgoMotionTable, link: LinkMotion, fit: LinkFit, ranked: list[LinkFit], similar: tuple[str, ...],
    declared_link: str, mounts: tuple[FloatArray, FloatArray | None], camera: str, turning: float,
    notes: list[str], opts: EgoMotionFitOptions, joint: Joint | None = None,
) -> EgoMotionFit:
    """Intervals by bootstrap on the final measurement (or on the joint fit's grid of measurements), observability,
    the mount against the declared one. ``mounts``: the declared mount, and the prior an unobservable axis keeps
    (None: the declared one)."""
    declared_q, prior = mounts
    origin = int(link.stamps_ns[0])
    span = (0.0, (int(link.stamps_ns[-1]) - origin) * 1e-9)
    orientations = Orientations(link, origin)
    if joint is not None and joint.solved.fine.size:
        pairs, solved = joint.pairs, joint.solved
    else:
        pairs = frame_pairs(table, origin, span, opts.max_offset_s)
        solved = solve(orientations, pairs, opts)
    boot = block_bootstrap(pairs, solved, opts)
    mount = solved.mount
    link_rv = link_rotvecs(orientations, pairs, np.array([solved.offset_s]))[0] - solved.bias * pairs.dt[:, None]
    info = information(orientations, pairs, solved, link_rv)
    short = too_short(pairs, opts)
    seen = Observed(short, ()) if short else observed(info)
    if seen.unobservable:
        notes.append(f"camera {camera}: {seen.unobservable}: its time offset and mount are not observable")
    elif seen.axes:
        notes.append(_one_axis_note(link.link, seen.axes[0], prior is None))
        kept, axis_link = matrix_of(declared_q if prior is None else prior), np.asarray(seen.axes[0])
        mount = complete_mount(solved.mount, kept, axis_link)
        boot = replace(boot, mounts=complete_mount(boot.mounts, kept, axis_link))
    mount_observable = not seen.unobservable
    undetermined = "" if seen.unobservable else offset_undetermined(solved, boot, opts)
    if undetermined:
        notes.append(f"time offset of camera {camera} is undetermined: {undetermined}")
    focal, focal_boot = focal_scale(pairs, solved, link_rv, boot)
    error = None
    if link.link == declared_link:
        angles = np.rad2deg(angle_of((Inverse(boot.mounts), declared_q)))
        rotvec = rotvec_of((Inverse(mount), declared_q))
        angle = float(np.linalg.norm(rotvec))
        axis = rotvec / angle if angle > 0 else np.array([0.0, 0.0, 1.0])
        error = MountError(angle_deg=float(np.rad2deg(angle)), axis=(float(axis[0]), float(axis[1]), float(axis[2])),
                           interval_deg=interval(angles))
    elif link.link not in similar or declared_link not in similar:
        notes.append(f"camera {camera} moves with {link.link}, not with the declared {declared_link}")
    links = (_chosen_fit(fit, solved, pairs, orientations), *[f for f in ranked if f.link != link.link])
    return EgoMotionFit(
        camera=camera, link=link.link, declared_link=declared_link,
        alternatives=tuple(name for name in similar if name != link.link), links=links,
        offset_s=solved.offset_s, offset_interval_s=interval(boot.offsets),
        q_link_cam=quat_of(mount), mount_error=error, focal_scale=focal, focal_scale_interval=interval(focal_boot),
        camera_rotation_deg=turning, offset_observable=not (undetermined or seen.unobservable),
        mount_observable=mount_observable, notes=tuple(notes), offset_undetermined=undetermined,
        unobservable=seen.unobservable, mount_unobservable_axes=seen.axes,
        bias_rad_s=(float(solved.bias[0]), float(solved.bias[1]), float(solved.bias[2])), table=table,
        evidence=mount_evidence(solved.weights, link_rv, pairs.rotvec, info.sigma_deg),
        link_misfits=tuple((f.link, f.residual_deg) for f in ranked),
    )


def _one_axis_note(link: str, axis: tuple[float, float, float], declared: bool) -> str:
    shown = ", ".join(f"{v:.2f}" for v in axis)
    kept = "as declared" if declared else "as fitted with the camera's position"
    return (f"link {link} turned about one axis only ([{shown}] in {link}) against the misfit: the camera's mount "
            f"rotation about that axis is not observable (it is kept {kept})")


def _chosen_fit(fit: LinkFit, solved: Solved, pairs: Pairs, orientations: Orientations) -> LinkFit:
    """The chosen link's fit as measured with its translation prior."""
    return link_fit(fit.link, pairs, solved, orientations)


#: A camera turned about one axis only whose translation moves the image the way its rotation across the optical axis
#: does, in more than this share of its frame pairs (weighted by that rotation), cannot tell the two apart: each
#: point's depth takes up part of the rotation, always in the same direction, and the focal length the rotation
#: implies is not measured. Generated SO-101 episodes: 0.99 and 1.00 where the arm only panned (a focal length 1.63
#: times the truth, "strong") or only rolled its wrist (right, by luck); where every joint moved, 0.04 to 0.85 (seed
#: 21) with the focal length within 1%: their turns about many axes tell rotation from translation.
SWUNG_SHARE = 0.8
#: Pairs whose rotation across the optical axis (rad) is under this are left out of that share.
SWUNG_MIN_ROTATION_RAD = 1e-4


def swung_share(table: EgoMotionTable) -> float:
    """The share of a camera's frame pairs, weighted by their rotation across the optical axis, whose measured
    translation moves the image's centre along the rotation's flow there (within 25 deg; 0 with no such pair).

    A rotation ``w`` (optical frame) moves the centre along ``(w_y, -w_x)``; a translation ``t`` along ``(t_x,
    t_y)``. Only pairs whose translation was measured (parallax of a pixel or more) are counted.
    """
    if not len(table):
        return 0.0
    rotvec = rotvec_of(table.quat_xyzw)
    flow = np.stack([rotvec[:, 1], -rotvec[:, 0]], axis=1)
    weight = np.linalg.norm(flow, axis=1)
    moved = table.direction[:, :2]
    seen = np.isfinite(moved).all(axis=1) & (weight > SWUNG_MIN_ROTATION_RAD) & (np.linalg.norm(
        np.nan_to_num(moved), axis=1) > 1e-9)
    if not seen.any():
        return 0.0
    cosine = np.abs((flow[seen] * moved[seen]).sum(axis=1)) / (weight[seen] * np.linalg.norm(moved[seen], axis=1))
    return float((weight[seen] * (cosine > np.cos(np.radians(25.0)))).sum() / weight[seen].sum())


def focal_hidden(fit: EgoMotionFit) -> float | None:
    """The share of swung frame pairs (:func:`swung_share`) when it hides the fit's focal length: an axis of the
    mount unobservable (a link turned about one axis) and over :data:`SWUNG_SHARE` of the pairs swung; else None."""
    if not fit.mount_unobservable_axes or fit.unobservable:
        return None
    swung = swung_share(fit.table)
    return swung if swung > SWUNG_SHARE else None
