"""The camera-motion fit's values: a candidate link's motion, the fit's options, and what it returns.

See :mod:`framechain.analysis.egomotion` for what the fit does.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Protocol

from framechain.arrays import FloatArray, IntArray
from framechain.timeline import EgoMotionTable, TranslationPrior

__all__ = ["EgoMotionFit", "EgoMotionFitOptions", "LinkFit", "LinkMotion", "Measure", "MountError", "MountEvidence"]

class Measure(Protocol):
    """Measures the camera's motion from its images, given a translation prior (None: rotation only); with
    ``rotations_only`` the rows and rotations alone (:func:`framechain.vision.egomotion.measure_egomotion`): what a
    fit's trials compare."""

    def __call__(self, prior: TranslationPrior | None, /, *, rotations_only: bool = False) -> EgoMotionTable: ...


@dataclass(frozen=True)
class LinkMotion:
    """Forward kinematics of one candidate link: ``R_base_link`` at the robot state's stamps.

    ``base`` may be any frame fixed in the world (the arm's base): only rotations between two
    times of the same link are compared.
    """

    link: str
    stamps_ns: IntArray  # (T,) strictly increasing
    quat_xyzw: FloatArray  # (T, 4)
    xyz: FloatArray | None = None  # (T, 3) the link's origin in the base: for the translation prior


@dataclass(frozen=True)
class EgoMotionFitOptions:
    """Search range and resolution of the offset, bootstrap size, observability thresholds."""

    max_offset_s: float = 0.5
    step_s: float = 0.01
    fine_step_s: float = 0.0005
    bootstrap: int = 200
    block_s: float = 0.5
    #: Below this RMS rotation per frame pair (deg) the camera (or link) is taken as not turning.
    min_rotation_deg: float = 0.05
    #: Links whose misfit is within this factor of the best fit explain the motion as well.
    same_fit_ratio: float = 1.25
    min_pairs: int = 20
    #: Fit a constant rate bias of the reference too (a gyro's; forward kinematics has none).
    rate_bias: bool = False
    #: The offset refined past the fine grid's parabola by a bounded scalar search (a ranking needs no such care).
    continuous: bool = True
    seed: int = 0

    def for_ranking(self) -> EgoMotionFitOptions:
        """The options candidate links are ranked with: offsets on a grid of 20 ms, refined on one of 2 ms at least
        (a ranking needs no finer, nor the continuous minimum past its parabola, and it fits every link)."""
        return replace(self, step_s=max(self.step_s, 0.02), fine_step_s=max(self.fine_step_s, 0.002), continuous=False)


@dataclass(frozen=True)
class LinkFit:
    """The best offset and mount for one candidate link, and how well they explain the images."""

    link: str
    offset_s: float
    q_link_cam: FloatArray  # (4,) xyzw, R_link_cam
    residual_deg: float  # robust RMS misfit per frame pair
    link_rotation_deg: float  # RMS rotation of the link per frame pair (0: the link does not turn)
    pairs: int
    #: The best offset of the coarse search lies at an end of its window: the true one may lie beyond it.
    at_window_edge: bool = False
    #: The reference's rate bias fitted (rad/s, in the link's frame; zeros unless ``rate_bias``).
    bias_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class MountError:
    """The declared mount against the measured one: ``R_declared = R_measured exp(angle * axis)``.

    ``axis`` is a unit vector in the camera's optical frame; ``interval_deg`` the 95% interval of
    the angle.
    """

    angle_deg: float
    axis: tuple[float, float, float]
    interval_deg: tuple[float, float]


@dataclass(frozen=True)
class MountEvidence:
    """What a fit's mount rests on, to be combined with other episodes' (:mod:`.recording`): at the fitted offset,
    ``cross = sum w a b^T`` and ``scatter = sum w a a^T`` of the link's (a) and camera's (b) rotation vectors, the
    weights' sum and the robust misfit per pair."""

    cross: FloatArray  # (3, 3)
    scatter: FloatArray  # (3, 3)
    weight: float
    sigma_deg: float

    def to_json(self) -> dict[str, Any]:
        return {"cross": [round(float(v), 9) for v in self.cross.ravel()],
                "scatter": [round(float(v), 9) for v in self.scatter.ravel()],
                "weight": round(self.weight, 6), "sigma_deg": round(self.sigma_deg, 6)}


@dataclass(frozen=True)
class EgoMotionFit:
    """What the camera's own motion says about its time offset, mount and link."""

    camera: str
    link: str  # the link the camera moves with (best fit), "" when the camera does not turn
    declared_link: str
    #: Other candidates explaining the motion as well (links rigid with ``link``, or an ambiguous fit).
    alternatives: tuple[str, ...]
    links: tuple[LinkFit, ...]  # every candidate, best first
    offset_s: float
    offset_interval_s: tuple[float, float]
    q_link_cam: FloatArray  # measured R_link_cam on ``link``
    mount_error: MountError | None  # against the declared mount, when ``link`` is the declared link
    #: Measured over predicted rotation across the optical axis: true / assumed focal length.
    focal_scale: float
    focal_scale_interval: tuple[float, float]
    camera_rotation_deg: float  # RMS measured rotation per frame pair
    offset_observable: bool
    mount_observable: bool
    notes: tuple[str, ...]
    #: Why the offset is undetermined ("" when it is not): at the edge of its search window, a flat misfit.
    offset_undetermined: str = ""
    #: Why neither offset nor mount can be seen ("" when they can): the link turns too little against the misfit.
    unobservable: str = ""
    #: Axes (unit, link frame) about which the mount is not observable (the link turned about them only).
    mount_unobservable_axes: tuple[tuple[float, float, float], ...] = ()
    #: The reference's rate bias fitted (rad/s, link frame; zeros unless the options ask for it).
    bias_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: The measurement the fit rests on (made with the chosen link's translation prior at the fitted offset).
    table: EgoMotionTable = field(default_factory=EgoMotionTable.empty)
    #: The sums the mount rests on (None: not measured), and every candidate's misfit on the final measurement.
    evidence: MountEvidence | None = None
    link_misfits: tuple[tuple[str, float], ...] = ()

    @property
    def wrong_link(self) -> bool:
        """The camera moves with another link than the declared one (and not with it as well)."""
        return bool(self.link) and self.link != self.declared_link and self.declared_link not in self.alternatives


