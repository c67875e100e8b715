"""One recording, one rig: each camera's link and mount fitted across its episodes, and each episode's own offset.

A camera screwed to a gripper stays on that gripper for the whole recording: its link and its mount are
the same in every episode, and only the video/state offset may move between sessions. Each episode is
fitted alone first (:mod:`.fit`, one work unit, on a pool or Ray); this module combines their results,
from what each episode's ``camera_motion`` entry carries (:class:`EpisodeCamera`):

- the **link**: the candidate whose misfit summed over the explained episodes is least, the declared
  one kept when within the fit's noise of it;
- the **mount**: one Kabsch fit of every episode's rotation pairs at once (the sums ``C = sum w a b^T``
  each episode keeps, at its own offset, with the forward kinematics translation in its measurement);
  about an axis the link turned too little across in *all* episodes together, it is kept as declared
  and the bound says so; its interval comes from resampling episodes (Bayesian weights);
- each episode's **offset** stays its own;
- an episode **departs** when its offset is further from the recording's median than it could find a
  latency of (its own bound), when its mount is further from the recording's than its own bound, when
  it moves with another link, or when the model does not explain its camera's motion; why is said.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from framechain.analysis.egomotion.bounds import angle_bound_deg, offset_bound_s
from framechain.analysis.egomotion.solve import complete_mount, principal_axes, weak_axes
from framechain.arrays import FloatArray
from framechain.geometry.rotations import angle_of, kabsch, matrix_of, quat_of

__all__ = ["CameraRecordingFit", "Departure", "EpisodeCamera", "fit_recording"]

#: A candidate link whose summed misfit is within this factor of the best explains the recording as well.
SAME_FIT_RATIO = 1.25
#: An episode departs from the recording when its offset (or mount) lies further from the recording's than this
#: many times its own bound: the recording's value has an error of its own, and generated episodes of one
#: recording differ by up to 4 ms and 1.5 deg where their bounds are 5 ms and 3 deg.
DEPARTURE_BOUNDS = 2.0


@dataclass(frozen=True)
class EpisodeCamera:
    """One camera in one episode, as its fit left it (its ``camera_motion`` entry)."""

    episode: int
    camera: str
    name: str | None
    link: str
    declared_link: str
    offset_s: float
    offset_interval_s: tuple[float, float]
    q_link_cam: FloatArray  # (4,) xyzw on ``link``
    declared_q_link_cam: FloatArray
    mount_half_width_deg: float  # half the width of the mount's 95% interval
    cross: FloatArray  # (3, 3) sum w a b^T at the fitted offset (link rotation vectors a, camera b)
    scatter: FloatArray  # (3, 3) sum w a a^T
    weight: float  # sum w
    sigma_deg: float  # robust RMS misfit per pair
    link_misfits: Mapping[str, float]
    explained: bool
    #: Its position on ``link`` fitted from its images, when it was not known (None: known, or not determined).
    xyz_link_cam: FloatArray | None = None
    #: The focal length its motion implies (px; NaN: not measured).
    focal_px: float = float("nan")

    @classmethod
    def from_entry(cls, episode: int, entry: Mapping[str, Any]) -> EpisodeCamera | None:
        """The camera of a ``camera_motion`` entry (None: its motion was not measured, or carries no evidence)."""
        evidence = entry.get("mount_evidence")
        if not entry.get("link") or not isinstance(evidence, Mapping) or entry.get("offset_s") is None:
            return None
        low, high = entry.get("offset_interval_s") or (entry["offset_s"], entry["offset_s"])
        mount = entry.get("mount_error_interval_deg") or (0.0, 0.0)
        return cls(
            episode=episode, camera=str(entry["camera"]), name=entry.get("name"), link=str(entry["link"]),
            declared_link=str(entry.get("declared_link") or ""), offset_s=float(entry["offset_s"]),
            offset_interval_s=(float(low), float(high)), q_link_cam=np.asarray(entry["q_link_cam"], dtype=float),
            declared_q_link_cam=np.asarray(evidence["declared_q_link_cam"], dtype=float),
            mount_half_width_deg=0.5 * (float(mount[1] or 0.0) - float(mount[0] or 0.0)),
            cross=np.asarray(evidence["cross"], dtype=float).reshape(3, 3),
            scatter=np.asarray(evidence["scatter"], dtype=float).reshape(3, 3), weight=float(evidence["weight"]),
            sigma_deg=float(evidence["sigma_deg"]), link_misfits=dict(entry.get("link_misfits") or {}),
            explained=entry.get("explained") is not False, xyz_link_cam=_fitted_position(entry),
            focal_px=float(entry.get("focal_scale") or np.nan) * float(entry.get("focal_px") or np.nan))

    @property
    def offset_bound_s(self) -> float:
        """How far from the recording's median its offset may lie (s)."""
        return DEPARTURE_BOUNDS * offset_bound_s(self.offset_interval_s)


@dataclass(frozen=True)
class Departure:
    """An episode whose camera departs from the recording's fit, and why."""

    episode: int
    camera: str
    what: str  # offset | mount | link | unexplained
    why: str

    def to_json(self) -> dict[str, Any]:
        return {"episode": self.episode, "camera": self.camera, "what": self.what, "why": self.why}


@dataclass(frozen=True)
class CameraRecordingFit:
    """One camera's link and mount over the whole recording, its episodes' offsets, and the episodes that depart."""

    camera: str
    name: str | None
    link: str
    declared_link: str
    q_link_cam: FloatArray  # (4,) xyzw on ``link``
    mount_interval_deg: tuple[float, float]  # the angle of resampled mounts from it, 95%
    mount_from_declared_deg: float  # its angle from the declared mount (NaN: another link than declared)
    unobservable_axes: tuple[tuple[float, float, float], ...]  # link frame: kept as declared
    median_offset_s: float
    episodes: tuple[EpisodeCamera, ...]
    episode_mount_deg: Mapping[int, float]  # each episode's mount's angle from the recording's
    departures: tuple[Departure, ...]
    #: The recording's episodes that gave this camera no measurement, each with why (not in ``episodes``).
    left_out: tuple[tuple[int, str], ...] = ()
    #: Its position on ``link``, not known: the median of the explained episodes' fits on it (None: none), how many
    #: they are and how far the farthest lies from it (m).
    xyz_link_cam: FloatArray | None = None
    position_episodes: int = 0
    position_spread_m: float = float("nan")
    #: The median of the focal lengths its explained episodes on ``link`` imply (px; NaN: none).
    focal_px: float = float("nan")

    @property
    def explained(self) -> tuple[EpisodeCamera, ...]:
        """The episodes whose motion the model explains: the recording's link, mount and offset rest on them."""
        return tuple(e for e in self.episodes if e.explained)

    def to_json(self) -> dict[str, Any]:
        return {
            "camera": self.camera, "name": self.name, "link": self.link if self.explained else None,
            "declared_link": self.declared_link,
            "q_link_cam": [round(float(v), 6) for v in self.q_link_cam] if self.explained else None,
            "mount_interval_deg": [_round(v) for v in self.mount_interval_deg] if self.explained else None,
            "mount_from_declared_deg": None if not np.isfinite(self.mount_from_declared_deg) else round(
                self.mount_from_declared_deg, 3),
            "unobservable_axes": [list(a) for a in self.unobservable_axes],
            "median_offset_s": _round(self.median_offset_s, 6) if self.explained else None,
            "episodes": [{"episode": e.episode, "link": e.link, "offset_s": round(e.offset_s, 6),
                          "offset_interval_s": [round(v, 6) for v in e.offset_interval_s],
                          "mount_from_recording_deg": _round(self.episode_mount_deg.get(e.episode)),
                          "explained": e.explained} for e in self.episodes],
            "departures": [d.to_json() for d in self.departures],
            "left_out": [{"episode": episode, "why": why} for episode, why in self.left_out],
            "position": None if self.xyz_link_cam is None else {
                "xyz_link_cam": [round(float(v), 6) for v in self.xyz_link_cam], "episodes": self.position_episodes,
                "farthest_episode_m": _round(self.position_spread_m, 6)},
        }


def fit_recording(cameras: Sequence[EpisodeCamera], *, seed: int = 0,
                  resamples: int = 200) -> tuple[CameraRecordingFit, ...]:
    """Each camera's recording-level fit (module text), from every episode's :class:`EpisodeCamera`."""
    names = list(dict.fromkeys(c.camera for c in cameras))
    return tuple(_one_camera([c for c in cameras if c.camera == name], seed, resamples) for name in names)


def _one_camera(episodes: list[EpisodeCamera], seed: int, resamples: int) -> CameraRecordingFit:
    episodes = sorted(episodes, key=lambda e: e.episode)
    first = episodes[0]
    link = _recording_link(episodes)
    on_link = [e for e in episodes if e.explained and e.link == link]
    declared = matrix_of(first.declared_q_link_cam)
    mount, axes = _mount(on_link, declared) if on_link else (matrix_of(first.q_link_cam), ())
    interval = _mount_interval(on_link, declared, mount, axes, seed, resamples)
    explained = [e for e in episodes if e.explained]
    median = float(np.median([e.offset_s for e in explained])) if explained else float("nan")
    angles = {e.episode: _angle_deg(_completed(matrix_of(e.q_link_cam), mount, axes), mount)
              for e in on_link}
    from_declared = _angle_deg(mount, declared) if link == first.declared_link else float("nan")
    placed = np.array([e.xyz_link_cam for e in on_link if e.xyz_link_cam is not None]).reshape(-1, 3)
    focal = [e.focal_px for e in on_link if np.isfinite(e.focal_px)]
    position = np.median(placed, axis=0) if len(placed) else None
    return CameraRecordingFit(
        camera=first.camera, name=first.name, link=link, declared_link=first.declared_link,
        q_link_cam=quat_of(mount), mount_interval_deg=interval,
        mount_from_declared_deg=from_declared, unobservable_axes=axes, median_offset_s=median,
        episodes=tuple(episodes), episode_mount_deg=angles,
        departures=tuple(_departures(episodes, link, median, angles)), xyz_link_cam=position,
        focal_px=float(np.median(focal)) if focal else float("nan"),
        position_episodes=len(placed),
        position_spread_m=float(np.linalg.norm(placed - position, axis=1).max()) if position is not None else np.nan)


def _fitted_position(entry: Mapping[str, Any]) -> FloatArray | None:
    """The position a ``camera_motion`` entry fitted from the images (None: the position was known)."""
    position = entry.get("position")
    if not isinstance(position, Mapping) or None in position.get("xyz_link_cam", [None]):
        return None
    return np.asarray(position["xyz_link_cam"], dtype=float)


def _recording_link(episodes: list[EpisodeCamera]) -> str:
    """The candidate of least misfit summed over the explained episodes (the declared one within the noise)."""
    explained = [e for e in episodes if e.explained and e.link_misfits] or episodes
    common = set.intersection(*(set(e.link_misfits) for e in explained)) if all(
        e.link_misfits for e in explained) else set()
    if not common:
        votes = [e.link for e in explained]
        return max(dict.fromkeys(votes), key=votes.count)
    totals = {name: sum(e.link_misfits[name] for e in explained) for name in sorted(common)}
    best = min(totals, key=lambda name: totals[name])
    declared = explained[0].declared_link
    return declared if declared in totals and totals[declared] <= SAME_FIT_RATIO * totals[best] else best


def _mount(episodes: list[EpisodeCamera], declared: FloatArray
           ) -> tuple[FloatArray, tuple[tuple[float, float, float], ...]]:
    """Kabsch on every episode's pairs at once; about an axis the link turned too little across in all of them
    together, the declared mount is kept."""
    mount: FloatArray = kabsch(np.sum(np.stack([e.cross for e in episodes]), axis=0))
    axes = _weak_axes(episodes)
    return _completed(mount, declared, axes), axes


def _weak_axes(episodes: list[EpisodeCamera]) -> tuple[tuple[float, float, float], ...]:
    """Link-frame axes the recording's link turned across too little for its misfit (:func:`weak_axes`)."""
    weight = sum(e.weight for e in episodes)
    sigma = float(np.sqrt(sum(e.weight * e.sigma_deg**2 for e in episodes) / max(weight, 1e-12)))
    axes, across_deg, _turning = principal_axes(np.sum(np.stack([e.scatter for e in episodes]), axis=0), weight)
    return weak_axes(axes, across_deg, sigma)


def _completed(mount: FloatArray, reference: FloatArray, axes: tuple[tuple[float, float, float], ...]) -> FloatArray:
    """``mount`` (..., 3, 3) turned about one unobservable axis to lie nearest ``reference`` (the reference itself for
    more)."""
    if not axes:
        return mount
    if len(axes) > 1:
        return reference
    out: FloatArray = complete_mount(mount, reference, np.asarray(axes[0]))
    return out


def _mount_interval(episodes: list[EpisodeCamera], declared: FloatArray, mount: FloatArray,
                    axes: tuple[tuple[float, float, float], ...], seed: int, resamples: int) -> tuple[float, float]:
    """The 95% interval of resampled mounts' angle from ``mount`` (episodes weighed by exponential draws)."""
    if len(episodes) < 2:
        return (float("nan"), float("nan"))
    rng = np.random.default_rng(seed)
    weights = rng.exponential(1.0, size=(resamples, len(episodes)))
    crosses = np.stack([e.cross for e in episodes])
    drawn = np.broadcast_to(_completed(kabsch(np.einsum("be,eij->bij", weights, crosses)), declared, axes),
                            (resamples, 3, 3))
    angles = np.rad2deg(angle_of(np.swapaxes(drawn, -1, -2) @ mount))
    low, high = np.percentile(angles, [2.5, 97.5])
    return float(low), float(high)


def _departures(episodes: list[EpisodeCamera], link: str, median: float,
                angles: Mapping[int, float]) -> list[Departure]:
    out = []
    for e in episodes:
        if not e.explained:
            out.append(Departure(e.episode, e.camera, "unexplained", "the model does not explain its camera's motion"))
        elif e.link != link and not _fits_as_well(e, link):
            out.append(Departure(e.episode, e.camera, "link", f"its camera moves with {e.link}, in the recording with "
                                 f"{link}"))
        elif abs(e.offset_s - median) > e.offset_bound_s:
            out.append(Departure(e.episode, e.camera, "offset", f"its offset ({e.offset_s * 1e3:+.1f} ms) departs from "
                                 f"the recording's median ({median * 1e3:+.1f} ms) by "
                                 f"{abs(e.offset_s - median) * 1e3:.1f} ms, more than the "
                                 f"{e.offset_bound_s * 1e3:.1f} ms it may (twice its bound)"))
        bound = DEPARTURE_BOUNDS * angle_bound_deg(e.mount_half_width_deg)
        if e.episode in angles and angles[e.episode] > bound:
            out.append(Departure(e.episode, e.camera, "mount", f"its mount is {angles[e.episode]:.1f} deg from the "
                                 f"recording's, more than the {bound:.1f} deg it may (twice its bound)"))
    return out


def _fits_as_well(episode: EpisodeCamera, link: str) -> bool:
    """The episode's camera fits ``link`` within SAME_FIT_RATIO of its own best link (the noise's choice between
    links that move alike, such as a gripper's jaw and its body, is no departure)."""
    misfits = episode.link_misfits
    return link in misfits and episode.link in misfits and misfits[link] <= SAME_FIT_RATIO * misfits[episode.link]


def _angle_deg(a: FloatArray, b: FloatArray) -> float:
    return float(np.rad2deg(angle_of(a.T @ b)))


def _round(value: float | None, digits: int = 3) -> float | None:
    return None if value is None or not np.isfinite(value) else round(float(value), digits)
