"""Each camera's own motion in a run: its frames decoded, its motion measured and fitted against the frame tree.

A camera whose images are in the timeline and whose frame hangs, through static edges, from a frame
that moves (a link driven by joint states, a base driven by odometry) turns as that frame turns. For
each such camera :func:`measure_cameras` has its frames decoded and tracked once (by the adapters,
handed in as ``images``: only the frames needed, long recordings in windows) and fits its time
offset, mount rotation and carrying link (:func:`~framechain.analysis.egomotion.fit_camera_motion`)
against candidate frames of the tree: the
declared link first, then every link that moves, on every arm (its parent, its child, the same link of
the other arm). Poses come from the run's transform buffer
(forward kinematics of a LeRobot episode, a log's tf), so nothing here knows the format.

A camera fixed in the world (a static chain up to the world frame) is said to be not observable,
without decoding anything.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Collection, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from framechain.analysis.egomotion import (
    EgoMotionFit,
    EgoMotionFitOptions,
    LinkFit,
    LinkMotion,
    fit_camera_motion,
    fit_link,
    rank_links,
)
from framechain.analysis.egomotion.fit import focal_hidden
from framechain.analysis.egomotion.position import PositionFit, fit_position
from framechain.arrays import FloatArray, IntArray
from framechain.config.calibration import Intrinsics
from framechain.config.chain import ChainConfig
from framechain.geometry.camera import is_a_lens
from framechain.geometry.rotations import IDENTITY, Rotations, quat_of, rotate_by
from framechain.replay import TransformBuffer
from framechain.timeline import EgoMotionTable, TranslationPrior
from framechain.vision.egomotion import FramePairCounts
from framechain.vision.opencv import opencv_threads
from framechain.vision.threads import forks, map_forked, run_threads, sharing_threads
from framechain.vision.two_view import PairBatch

__all__ = ["CameraImages", "CameraMotion", "CameraMotionEvidence", "ImagesOf", "measure_cameras"]

#: At most this many candidate frames are ranked per camera (two six-joint arms have a dozen moving links).
MAX_CANDIDATES = 24


class CameraImages(Protocol):
    """A camera's frames, decoded and tracked once (the adapters' :class:`~framechain.adapters.messages.
    egomotion_frames.ImageMotion`): measured against any translation prior."""

    frames: int  # frames used
    decoded: int  # frames decoded
    intrinsics: Intrinsics  # as measured with (declared, or assumed from the image size)
    intrinsics_known: bool
    notes: tuple[str, ...]
    last: EgoMotionTable  # the latest complete measurement
    pairing: str  # how a video's frames pair with the rows ("" for images stamped on their own)
    forced: bool  # the pairing was forced in the configuration
    alternatives: dict[str, IntArray]  # the frames' stamps under the other pairings

    def measure(self, prior: TranslationPrior | None, /, *, rotations_only: bool = False) -> EgoMotionTable:
        """The camera's motion given a translation prior (a :class:`~framechain.analysis.egomotion.model.Measure`)."""

    def rescale_focal(self, factor: float) -> None:
        """Measure from now on with the focal length scaled by ``factor``."""

    def pair_counts(self) -> FramePairCounts:
        """The frame pairs the usable frames give and those left out before measuring (under the pairing used)."""

    def pair_bearings(self) -> tuple[PairBatch, IntArray, IntArray] | None:
        """The measured frame pairs' matched bearings and their frames' stamps (None: no pair)."""

    def restamp(self, table: EgoMotionTable, pairing: str) -> EgoMotionTable:
        """A measurement with its frames stamped under another pairing."""

    def use_pairing(self, pairing: str) -> None:
        """Measure from now on with the frames stamped under ``pairing``."""


#: Decodes and tracks the images of a camera (its frame), only when its motion is worth measuring.
ImagesOf = Callable[[str], CameraImages]


@dataclass(frozen=True)
class CameraMotion:
    """One camera's motion evidence: what it is declared on, the fit (None: not measured) and why not."""

    camera: str  # the optical frame, as in the chain
    declared_link: str  # the moving frame the camera hangs from through static edges ("" fixed in the world)
    declared_q_link_cam: FloatArray  # (4,) xyzw
    declared_xyz_link_cam: FloatArray  # (3,)
    fit: EgoMotionFit | None
    table: EgoMotionTable  # the final measurement (empty when not measured)
    links: tuple[LinkMotion, ...]  # the candidates, declared first
    frames: int = 0  # frames used (0: none decoded)
    decoded: int = 0
    seconds: float = 0.0
    intrinsics_known: bool = True
    notes: tuple[str, ...] = ()
    #: The focal length ``table`` was measured with, over the declared one (1: as declared).
    measured_focal: float = 1.0
    #: The declared (or assumed) focal length and image width (px): what a lens can be is judged on them.
    focal_px: float = float("nan")
    width_px: int = 0
    #: How the camera's video frames pair with the rows, and what the motion says of it ("" when not a video).
    pairing: str = ""
    #: The frame pairs the usable frames gave, and those left out before measuring (None: not measured).
    pair_counts: FramePairCounts | None = None
    #: The camera's position on its link fitted from its matches, when it was not known (None: not fitted).
    position: PositionFit | None = None
    #: Its mount and lens are guesses (a robot.yaml framechain made): only what the motion shows of them is known.
    guessed: bool = False

    @property
    def xyz_link_cam(self) -> FloatArray:
        """The camera's position on its link the fit used: fitted when it was not known, else declared."""
        return self.declared_xyz_link_cam if self.position is None else self.position.xyz_link_cam

    def pairs_left_out(self) -> dict[str, int]:
        """The frame pairs possible but not in ``table``, by why (empty when not measured): with fewer than
        ``min_inliers`` matched moving features, stamped out of order, or with fewer inliers after measuring."""
        counts = self.pair_counts
        if counts is None:
            return {}
        return {"too_few_matched_features": counts.few_matches, "stamps_out_of_order": counts.unordered,
                "too_few_inliers": counts.gathered - len(self.table)}

    @property
    def observable(self) -> bool:
        """The camera turned enough to measure its offset or mount."""
        return self.fit is not None and bool(self.fit.link)

    @property
    def why_not(self) -> str:
        """Why the camera's motion says nothing ("" when it does)."""
        if self.observable:
            return ""
        if self.fit is not None and self.fit.notes:
            return self.fit.notes[0]
        return next(iter(self.notes), f"camera {self.camera}: its motion was not measured")

    def link_motion(self, name: str) -> LinkMotion:
        return next(link for link in self.links if link.link == name)


@dataclass(frozen=True)
class CameraMotionEvidence:
    """Every camera's motion evidence in a run (chain camera first)."""

    cameras: tuple[CameraMotion, ...]

    def of(self, camera: str) -> CameraMotion | None:
        return next((c for c in self.cameras if c.camera == camera), None)

    @property
    def observable(self) -> tuple[CameraMotion, ...]:
        return tuple(c for c in self.cameras if c.observable)


def measure_cameras(
    chain: ChainConfig, buffer: TransformBuffer, cameras: Sequence[str], images: ImagesOf, *,
    options: EgoMotionFitOptions | None = None, progress: Callable[[str], None] | None = None,
    guessed: Collection[str] = (),
) -> CameraMotionEvidence | None:
    """Each of ``cameras`` (frames with images; ``images`` decodes them) measured (None: no camera). The mounts and
    intrinsics of ``guessed`` are guesses (a robot.yaml framechain made): each one's position on its link is fitted
    from its images (:mod:`.position`), and its lens is reported as guessed."""
    if not cameras:
        return None
    order = sorted(cameras, key=lambda f: f != chain.frames.camera)  # the chain's camera first
    if progress is not None:
        many = len(order) > 1
        progress(f"measuring the motion of {'cameras' if many else 'camera'} {', '.join(order)} from "
                 f"{'their' if many else 'its'} images")
    opts = options or EgoMotionFitOptions()
    if chain.evidence.camera_offset_window_s is not None:
        opts = replace(opts, max_offset_s=chain.evidence.camera_offset_window_s)
    # The cameras' fits are independent: each in a process of its own where this process may fork (no lock of the
    # interpreter's shared), else on a thread of its own (PyAV, OpenCV and NumPy release that lock for most of the
    # work); a log's reader fetches for one at a time.
    workers = max(1, min(len(order), run_threads()))
    share = max(1, run_threads() // workers)

    def measured(camera: str) -> CameraMotion:
        with sharing_threads(share):
            return _measure_camera(chain, buffer, camera, images, opts, guessed=camera in guessed)

    with opencv_threads(1) if workers > 1 else contextlib.nullcontext():
        if forks():
            out = map_forked(measured, order, workers)
        else:
            with ThreadPoolExecutor(max_workers=workers) as pool:
                out = list(pool.map(measured, order))
    return CameraMotionEvidence(cameras=tuple(out))


def _measure_camera(chain: ChainConfig, buffer: TransformBuffer, camera: str, images: ImagesOf,
                    options: EgoMotionFitOptions, *, guessed: bool = False) -> CameraMotion:
    start = time.perf_counter()
    link, q_link_cam, xyz_link_cam = _declared_mount(buffer, camera)
    empty = CameraMotion(camera=camera, declared_link=link, declared_q_link_cam=q_link_cam,
                         declared_xyz_link_cam=xyz_link_cam, fit=None, table=EgoMotionTable.empty(), links=())
    if not link or not _moves(buffer, chain.frames.world, link):
        why = (f"camera {camera} is fixed in {chain.frames.world} (no moving frame above it): its time offset, mount "
               "and link are not observable from its own motion")
        return replace(empty, notes=(why,), seconds=time.perf_counter() - start)
    candidates = _candidates(buffer, link)
    links = tuple(m for m in (_link_motion(buffer, chain.frames.world, name) for name in candidates) if m is not None)
    if not links or links[0].link != link:
        why = f"camera {camera}: the poses of {link} cannot be looked up in {chain.frames.world} at its samples"
        return replace(empty, notes=(why,), seconds=time.perf_counter() - start)
    source = images(camera)
    declared = source.intrinsics
    pairing, measured = confirm_pairing(source, links, camera, options)
    fitted = _fit_with_focal(source, links, camera, (link, q_link_cam, xyz_link_cam), options, measured,
                             position_unknown=guessed)
    fit = fitted.fit
    return CameraMotion(camera=camera, declared_link=link, declared_q_link_cam=q_link_cam,
                        declared_xyz_link_cam=xyz_link_cam, fit=fit,
                        table=fit.table if len(fit.table) else source.last, links=links,
                        frames=source.frames, decoded=source.decoded, seconds=time.perf_counter() - start,
                        intrinsics_known=source.intrinsics_known and not guessed,
                        notes=(*source.notes, *pairing, *fitted.notes),
                        measured_focal=fitted.focal, focal_px=0.5 * (declared.fx + declared.fy),
                        width_px=declared.width, pairing=source.pairing, pair_counts=source.pair_counts(),
                        position=fitted.position, guessed=guessed)


#: Another pairing whose misfit is this many times smaller contradicts the one the files gave.
PAIRING_CONTRADICTED = 1.5


def confirm_pairing(source: CameraImages, links: Sequence[LinkMotion], camera: str, options: EgoMotionFitOptions
                    ) -> tuple[list[str], tuple[EgoMotionTable, list[LinkFit]] | None]:
    """What the camera's motion says of how its video frames were paired with the rows, as notes, and the
    rotation-only measurement with its ranking when they stand for the pairing used (for the fit to start from).

    The rotation-only measurement is fitted (offset and mount, every candidate link) with the frames
    stamped as paired, and as every other pairing would stamp them: under a wrong pairing the misfit
    is much larger. When another pairing fits :data:`PAIRING_CONTRADICTED` times better, a pairing the
    files suggested is replaced by it, and a pairing forced in the configuration stays, with a note.
    """
    if not source.pairing or not source.alternatives:
        return [], None
    table = source.measure(None)
    ranked = rank_links(table, links, options)
    measured = (table, ranked)
    if not ranked:
        return [], measured
    # The other pairings on the link that fits best as paired: a wrong pairing is much worse on any link.
    link = next(m for m in links if m.link == ranked[0].link)
    own = _misfit_of(table, link, options)
    if own is None:
        return [], measured
    others = {name: _misfit_of(source.restamp(table, name), link, options) for name in source.alternatives}
    scored = sorted((v, k) for k, v in others.items() if v is not None)
    said = "; ".join(f"{v:.3f} by {k}" for v, k in scored)
    if not scored or scored[0][0] * PAIRING_CONTRADICTED >= own:
        return [f"camera {camera}: its motion confirms its frames' pairing by {source.pairing} (misfit {own:.3f} deg "
                f"per frame pair against forward kinematics; {said})"], measured
    best, name = scored[0]
    if source.forced:
        return [f"camera {camera}: its frames are paired with the rows by {source.pairing}, as the configuration "
                f"forces, but its motion contradicts it: the misfit against forward kinematics is {own:.3f} deg per "
                f"frame pair, and {best:.3f} by {name}"], measured
    was = source.pairing
    source.use_pairing(name)
    return [f"camera {camera}: the files suggested pairing its frames with the rows by {was}, but its motion fits "
            f"forward kinematics much better by {name} ({best:.3f} against {own:.3f} deg misfit per frame pair): "
            f"paired by {name}"], None  # measured again under the new pairing


def _misfit_of(table: EgoMotionTable, link: LinkMotion, options: EgoMotionFitOptions) -> float | None:
    """The link's rotation-only misfit (deg per frame pair), offset and mount fitted as for a ranking (None: too few
    pairs): a wrong pairing is off by far more than the offset's last millisecond."""
    fit = fit_link(table, link, options.for_ranking())
    return None if fit is None else fit.residual_deg


#: Rounds of measuring again with the focal length the motion implies, when it is clearly not the declared one.
FOCAL_ROUNDS = 3


@dataclass(frozen=True)
class _Fitted:
    """A camera's fit, the focal length its final measurement used (over the declared one), what it says of both,
    and its position on its link when that was fitted."""

    fit: EgoMotionFit
    focal: float
    notes: list[str]
    position: PositionFit | None = None


def _fit_with_focal(source: CameraImages, links: Sequence[LinkMotion], camera: str,
                    declared: tuple[str, FloatArray, FloatArray], options: EgoMotionFitOptions,
                    measured: tuple[EgoMotionTable, list[LinkFit]] | None = None, *,
                    position_unknown: bool = False) -> _Fitted:
    """The fit, measured again with the focal length it implies while that clearly differs from the one used.

    A wrong focal length scales the rotation seen across the optical axis; the mount and offset fits
    absorb part of it (a few degrees, ten milliseconds). Measuring again with the implied one takes
    it out; the step is squared because each round recovers about half of what is left. The fit's focal
    scale is over the *declared* focal length. When the camera's position on its link is not known
    (``position_unknown``), it is fitted from the matches with the focal length (:mod:`.position`) after the
    first fit, and the camera measured again from there.
    """
    used = 1.0
    notes: list[str] = []
    link, q_link_cam, xyz_link_cam = declared

    def fitted() -> EgoMotionFit:
        return fit_camera_motion(source.measure, links, camera=camera, declared_link=link,
                                 declared_q_link_cam=q_link_cam, declared_xyz_link_cam=xyz_link_cam, options=options,
                                 measured=measured if used == 1.0 and position is None else None,
                                 mount_prior=None if position is None else position.q_link_cam)

    position = None
    fit = fitted()
    if position_unknown and fit.link:
        position, note = _fitted_position(source, links, camera, fit, options)
        notes.append(note)
        if position is not None:
            source.rescale_focal(position.focal_factor)
            used *= position.focal_factor
            xyz_link_cam = position.xyz_link_cam
            fit = fitted()
    for _ in range(FOCAL_ROUNDS):
        low, high = fit.focal_scale_interval
        if not fit.link or not np.isfinite(fit.focal_scale) or low <= 1.0 <= high or abs(fit.focal_scale - 1) < 0.02:
            break
        if focal_hidden(fit) is not None:  # the focal length it implies is not measured: nothing to measure again with
            break
        step = fit.focal_scale**2
        lens = source.intrinsics
        if not is_a_lens(lens.width, 0.5 * (lens.fx + lens.fy) * step):  # no lens's: measuring with it shows nothing
            break
        source.rescale_focal(step)
        used *= step
        fit = fitted()
    if used != 1.0:
        notes.append(f"camera {camera}: its motion implied another focal length; measured again with "
                     f"{used:.3f} times the declared one")
        low, high = fit.focal_scale_interval
        fit = replace(fit, focal_scale=fit.focal_scale * used, focal_scale_interval=(low * used, high * used))
    return _Fitted(fit, used, notes, position)


def _fitted_position(source: CameraImages, links: Sequence[LinkMotion], camera: str, fit: EgoMotionFit,
                     options: EgoMotionFitOptions) -> tuple[PositionFit | None, str]:
    """The camera's position on the link it rides, fitted from its matches (None when it cannot be), and a note."""
    gathered = source.pair_bearings()
    link = next(m for m in links if m.link == fit.link)
    focal = 0.5 * (source.intrinsics.fx + source.intrinsics.fy)
    # From the rotation-only fit's mount and offset: measured with a translation from the wrong position, the fit's
    # own mount can be anywhere (on generated SO-101 episodes 40 to 170 deg off; the rotation-only one 5 to 10).
    start = fit_link(source.measure(None), link, options) or fit
    position = None if gathered is None else fit_position(
        *gathered, link, q_link_cam=start.q_link_cam, xyz_link_cam=np.zeros(3), offset_s=start.offset_s,
        focal_px=focal, max_offset_s=options.max_offset_s)
    if position is None:
        return None, (f"camera {camera}: its position on {fit.link} is not known and could not be fitted from its "
                      "images (no frame pair inside the link's span, or the link has no positions): measured at the "
                      "link's origin")
    before, after = position.residual_px
    axis = ", ".join(f"{v:.2f}" for v in position.spread_axes[0])
    said = (f"its position on {fit.link} is not known; fitted from {position.matches:,} matched features in "
            f"{position.pairs:,} frame pairs: xyz [{', '.join(f'{v:.3f}' for v in position.xyz_link_cam)}] m "
            f"({_spread_said(float(position.spread_m[0]))} along [{axis}], 1 sd), focal length "
            f"{position.focal_factor * focal:.1f} px (median residual {after:.2f} px, {before:.2f} at the link's "
            "origin)")
    if position.undetermined:
        return None, (f"camera {camera}: {said}, but {position.undetermined}: not used, measured at the link's origin; "
                      "measure the camera's position on its link")
    return position, f"camera {camera}: {said}; measured there"


def _spread_said(metres: float) -> str:
    return f"+-{metres * 1e3:.1f} mm" if metres < 1.0 else "over +-1 m"


# -- the frame tree ------------------------------------------------------------------------------------
def _declared_mount(buffer: TransformBuffer, camera: str) -> tuple[str, FloatArray, FloatArray]:
    """The first frame above ``camera`` reached through a moving edge, and the static ``T_link_cam`` to it.

    ("", identity, zeros) when the camera is not in the tree; the root when every edge above is static.
    """
    edges = buffer.edges
    rotation: Rotations = IDENTITY
    translation = np.zeros(3)
    current = camera
    if current not in edges:
        return "", np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3)
    while current in edges and edges[current].is_static:
        edge = edges[current]
        step = edge.quat_xyzw[-1]
        translation = edge.translation[-1] + rotate_by(step, translation)
        rotation = (step, rotation)  # each edge's rotation composed onto those below it, as they are climbed
        current = edge.parent
    return current, quat_of(rotation), translation


def _moves(buffer: TransformBuffer, world: str, link: str) -> bool:
    """Some edge between ``world`` and ``link`` is dynamic."""
    path = buffer.path(world, link)
    return path.connected and any(not hop.is_static for hop in path.hops)


def _candidates(buffer: TransformBuffer, link: str) -> list[str]:
    """The declared link first, then every link that moves: every child of a moving edge, on every arm (a camera
    declared on a link may ride its parent, its child or the same link of the other arm)."""
    moving = [child for child, edge in buffer.edges.items() if not edge.is_static]
    return list(dict.fromkeys([link, *moving]))[:MAX_CANDIDATES]


def _link_motion(buffer: TransformBuffer, world: str, link: str) -> LinkMotion | None:
    """``T_world_link`` at the samples of the link's own moving edge (None: fewer than ten usable)."""
    edges = buffer.edges
    frame: str | None = link
    while frame is not None and frame in edges and edges[frame].is_static:
        frame = edges[frame].parent
    if frame is None or frame not in edges:
        return None
    stamps = edges[frame].stamps_ns
    found = buffer.lookup(world, link, stamps)
    ok = found.ok
    if int(ok.sum()) < 10:
        return None
    return LinkMotion(link=link, stamps_ns=stamps[ok].astype(np.int64), quat_xyzw=found.quat_xyzw[ok],
                      xyz=found.translation[ok])
