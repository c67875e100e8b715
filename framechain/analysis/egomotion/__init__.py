"""A camera's own motion as evidence: its rotation measured from its images against forward kinematics.

- :mod:`.model`: a candidate link's motion, the fit's options and results;
- :mod:`.solve` and :mod:`.fit`: the time offset, mount rotation and carrying link that explain the
  measured rotation, with intervals and what the motion can show at all;
- :mod:`.run`: each camera of a run measured (its frames decoded by the adapters) and fitted;
- :mod:`.bounds`: whether the motion is explained, which estimates are undetermined, the bounds;
- :mod:`.findings`: the corrections as findings with their fixes; :mod:`.attribution`: into the run's attribution.
"""

from __future__ import annotations

from framechain.analysis.egomotion.fit import (
    RotationRates,
    fit_camera_motion,
    fit_link,
    rank_links,
    rotation_rates,
    translation_prior,
)
from framechain.analysis.egomotion.model import (
    EgoMotionFit,
    EgoMotionFitOptions,
    LinkFit,
    LinkMotion,
    Measure,
    MountError,
)
from framechain.analysis.egomotion.solve import complete_mount

__all__ = [
    "EgoMotionFit",
    "EgoMotionFitOptions",
    "LinkFit",
    "LinkMotion",
    "Measure",
    "MountError",
    "RotationRates",
    "complete_mount",
    "fit_camera_motion",
    "fit_link",
    "rank_links",
    "rotation_rates",
    "translation_prior",
]
