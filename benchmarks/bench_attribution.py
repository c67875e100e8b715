"""Attribution accuracy over many generated scenes (a benchmark, not a test).

The scenes come from :mod:`framechain.sim`, whose truth is computed with its own maths (never
framechain's replay), so a bug in the product shows here instead of cancelling out. For each
evidence level: N scenes, each with one fault drawn round-robin from the level's catalogue of
fault forms (the real forms included: the optical edge dropped, base_footprint looked up for
base_link, a stale pose held, the mount published inverted, the camera_info of another
resolution, the depth imager's frame looked up for the colour one), with random seed, noise,
motion and fault size; and N/2 clean scenes. Reports, per level and per fault form: the share
whose top finding names the right fault and hop (and, for the frame swaps, the frame used), the
share whose estimate is within the generator's tolerance, and the share of clean scenes with a
finding above a 0.1 share (false positives). Targets: top finding right in 100% of
hops, target and reference scenes and 95% of static ones.

    python benchmarks/run.py attribution            # N = 200 per level
    FRAMECHAIN_BENCH_SCENES=40 FRAMECHAIN_BENCH_LEVELS=reference,static python benchmarks/run.py attribution
"""

from __future__ import annotations

import os
import time
from collections import defaultdict
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

from framechain import pipeline
from framechain.catalogue import Fault
from framechain.sim.scene import REALSENSE_OPTICAL_FRAME, REALSENSE_OPTICAL_XYZ, InjectedFault, SceneSpec, generate

LEVELS = ("hops", "target", "reference", "static")
TARGETS = {"hops": 1.0, "target": 1.0, "reference": 1.0, "static": 0.95}
PROPER_FLIPS = [[[-1, 0, 0], [0, -1, 0], [0, 0, 1]], [[1, 0, 0], [0, -1, 0], [0, 0, -1]],
                [[0, 1, 0], [-1, 0, 0], [0, 0, 1]]]
ANY_FLIPS = [*PROPER_FLIPS, [[1, 0, 0], [0, -1, 0], [0, 0, 1]], [[0, 0, 1], [1, 0, 0], [0, 1, 0]]]

Draw = Callable[[np.random.Generator, str], InjectedFault]


def _sign(rng: np.random.Generator) -> float:
    return float(rng.choice([-1.0, 1.0]))


def _rotation(rng: np.random.Generator, where: str) -> InjectedFault:
    axis = rng.normal(size=3)
    return InjectedFault(Fault.ROTATION_ERROR, where,  # type: ignore[arg-type]
                         {"angle_deg": float(rng.uniform(1.0, 6.0)), "axis": (axis / np.linalg.norm(axis)).tolist()})


def _unit_vector(rng: np.random.Generator) -> np.ndarray:
    axis = rng.normal(size=3)
    out: np.ndarray = axis / np.linalg.norm(axis)
    return out


def _flip(rng: np.random.Generator, where: str) -> InjectedFault:
    options = PROPER_FLIPS if where == "data" else ANY_FLIPS  # the data can only carry a proper rotation
    return InjectedFault(Fault.AXIS_FLIP, where, {"permutation": options[int(rng.integers(len(options)))]})  # type: ignore[arg-type]


#: Fault forms by name: each draws one fault of random size where it is asked to live.
FORMS: dict[str, Draw] = {
    "latency": lambda rng, where: InjectedFault(
        Fault.LATENCY, where, {"offset_s": round(_sign(rng) * float(rng.uniform(0.01, 0.08)), 4)}),  # type: ignore[arg-type]
    "stale_pose_held": lambda rng, where: InjectedFault(
        Fault.LATENCY, where, {"hold_s": round(float(rng.uniform(0.02, 0.08)), 4)}),  # type: ignore[arg-type]
    "rotation_error": _rotation,
    "missing_rotation": lambda rng, where: InjectedFault(Fault.MISSING_ROTATION, where),  # type: ignore[arg-type]
    "axis_flip": _flip,
    "optical_edge_dropped": lambda rng, where: InjectedFault(
        Fault.AXIS_FLIP, where, {"used": "camera_link"}),  # type: ignore[arg-type]
    "translation_error": lambda rng, where: InjectedFault(
        Fault.TRANSLATION_ERROR, where, {"offset_m": (_unit_vector(rng) * rng.uniform(0.02, 0.10)).tolist()}),  # type: ignore[arg-type]
    "depth_scale": lambda rng, where: InjectedFault(
        Fault.DEPTH_SCALE, where, {"factor": float(1.0 + _sign(rng) * rng.uniform(0.03, 0.15))}),  # type: ignore[arg-type]
    "intrinsics": lambda rng, where: InjectedFault(
        Fault.INTRINSICS, where, {"scale": float(rng.choice([0.5, 0.75, 1.5]))}),  # type: ignore[arg-type]
    "camera_info_1280x960": lambda rng, where: InjectedFault(
        Fault.INTRINSICS, where, {"scale": 2.0}),  # type: ignore[arg-type]
    "depth_frame_for_colour": lambda rng, where: InjectedFault(
        Fault.WRONG_CAMERA_FRAME, where, {"used": "camera_depth_optical_frame"}),  # type: ignore[arg-type]
    "odom_for_map": lambda rng, where: InjectedFault(Fault.WRONG_WORLD_FRAME, where),  # type: ignore[arg-type]
    "base_footprint_for_base_link": lambda rng, where: InjectedFault(
        Fault.WRONG_WORLD_FRAME, where,  # type: ignore[arg-type]
        {"used": "base_footprint", "footprint_height_m": round(float(rng.uniform(0.04, 0.15)), 3)}),
    "inverted_camera_to_body": lambda rng, where: InjectedFault(
        Fault.INVERTED_TRANSFORM, where, {"hop": "camera_to_body"}),  # type: ignore[arg-type]
    "inverted_body_to_world": lambda rng, where: InjectedFault(
        Fault.INVERTED_TRANSFORM, where, {"hop": "body_to_world"}),  # type: ignore[arg-type]
}
# What each level can see: the robot's own points (hops, target) show the robot's mistakes; a
# reference or the static target's spread shows faults in the recorded data.
ROBOT_FORMS = list(FORMS)
DATA_FORMS = ["latency", "rotation_error", "translation_error", "missing_rotation", "axis_flip", "depth_scale",
              "intrinsics",
              "camera_info_1280x960", "inverted_camera_to_body",  # the mount published inverted
              "optical_edge_dropped"]  # the detections name camera_link while their pixels are optical


def forms_for(level: str) -> tuple[str, list[str]]:
    if level == "static":
        # The generated base only turns about z: a static target shows a mount's position only through the arc its
        # offset draws within one window (and never along z); the bounds say how far (tens of millimetres). It is
        # measured against a reference, logged hops and a target instead.
        return "data", [f for f in DATA_FORMS if f != "translation_error"]
    return ("data", DATA_FORMS) if level == "reference" else ("robot", ROBOT_FORMS)


def one_case(args: tuple[str, int, bool]) -> dict[str, Any]:
    level, seed, clean = args
    rng = np.random.default_rng(10_000 + seed)
    where, forms = forms_for(level)
    form = forms[seed % len(forms)]
    fault = None if clean else FORMS[form](rng, where)
    # Mostly a RealSense's colour optical frame (15 mm off camera_link; the depth-frame swap needs it).
    realsense = bool(rng.random() < 0.75) or form == "depth_frame_for_colour"
    spec = SceneSpec(
        seed=seed, duration_s=float(rng.uniform(6.0, 10.0)), evidence=level,  # type: ignore[arg-type]
        pixel_noise_px=float(rng.uniform(0.2, 1.0)), depth_noise_rel=float(rng.uniform(0.001, 0.006)),
        orbit_rate=float(rng.uniform(0.12, 0.38) * rng.choice([-1, 1])), wobble_rad=float(rng.uniform(0.05, 0.22)),
        mount_pitch_deg=float(rng.uniform(15.0, 35.0)),
        optical_frame=REALSENSE_OPTICAL_FRAME if realsense else "camera_optical_frame",
        optical_xyz=REALSENSE_OPTICAL_XYZ if realsense else (0.0, 0.0, 0.0),
        faults=() if fault is None else (fault,),
    )
    scene = generate(spec)
    started = time.perf_counter()
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    out: dict[str, Any] = {"level": level, "clean": clean, "seconds": time.perf_counter() - started}
    findings = [f.to_json() for f in result.findings]  # estimates read through JSON: dicts or typed objects
    if clean:
        out["false_positive"] = any(f["share"] > 0.1 and f.get("actionable", True) for f in findings)
        return out
    (expected,) = scene.expected_findings
    top = findings[0] if findings else None
    out["form"] = form
    out["right"] = top is not None and expected.names(top["fault"], top["hop"], top["estimate"])
    out["got"] = "nothing" if top is None else f"{top['fault']}@{top['hop']} {_short(top['estimate'])}"
    if out["right"] and expected.estimate and top is not None:
        out["estimate_within"] = expected.estimate_within(top["estimate"])
        out["estimate_note"] = f"want {_short(expected.estimate)} got {_short(top['estimate'])}"
    return out


def _short(estimate: dict[str, Any]) -> str:
    keep = ("offset_s", "angle_deg", "distance_m", "factor", "scale", "used", "meant", "permutation", "edge", "hop")
    parts = []
    for key in keep:
        if key in estimate:
            value = estimate[key]
            parts.append(f"{key}={value:.4g}" if isinstance(value, float) else f"{key}={value}")
    return "{" + ", ".join(parts) + "}"


def main() -> None:
    n = int(os.environ.get("FRAMECHAIN_BENCH_SCENES", "200"))
    levels = [lv for lv in os.environ.get("FRAMECHAIN_BENCH_LEVELS", ",".join(LEVELS)).split(",") if lv in LEVELS]
    n_clean = max(n // 2, 1)
    cases = [(level, seed, False) for level in levels for seed in range(n)]
    cases += [(level, 50_000 + seed, True) for level in levels for seed in range(n_clean)]
    started = time.perf_counter()
    with ProcessPoolExecutor(max_workers=min(2, os.cpu_count() or 1)) as pool:
        results = list(pool.map(one_case, cases, chunksize=2))
    wall = time.perf_counter() - started
    print(f"attribution accuracy (independent scene generator): {n} faulted + {n_clean} clean scenes per level, "
          f"{wall:.0f} s wall")
    for level in levels:
        rows = [r for r in results if r["level"] == level and not r["clean"]]
        clean = [r for r in results if r["level"] == level and r["clean"]]
        right = float(np.mean([r["right"] for r in rows]))
        checked = [r["estimate_within"] for r in rows if "estimate_within" in r]
        within = f"{np.mean(checked):.1%} of {len(checked)}" if checked else "n/a"
        fp = float(np.mean([r["false_positive"] for r in clean]))
        seconds = float(np.median([r["seconds"] for r in rows]))
        print(f"  {level:9s} top finding right {right:.1%} (target {TARGETS[level]:.0%}); estimate within tolerance "
              f"{within}; clean scenes with a finding above 0.1 share {fp:.1%}; median {seconds:.2f} s/scene")
        by_form: dict[str, list[dict[str, Any]]] = defaultdict(list)
        for r in rows:
            by_form[r["form"]].append(r)
        for form in forms_for(level)[1]:
            form_rows = by_form.get(form, [])
            if not form_rows:
                continue
            n_right = sum(r["right"] for r in form_rows)
            form_checked = [r for r in form_rows if "estimate_within" in r]
            est = (f"; estimate within {sum(r['estimate_within'] for r in form_checked)}/{len(form_checked)}"
                   if form_checked else "")
            print(f"    {form:30s} right {n_right}/{len(form_rows)}{est}")
            misses: dict[str, int] = defaultdict(int)
            for r in form_rows:
                if not r["right"]:
                    misses[r["got"]] += 1
                elif not r.get("estimate_within", True):
                    misses["estimate off: " + r["estimate_note"]] += 1
            for got, count in sorted(misses.items(), key=lambda kv: -kv[1])[:3]:
                print(f"        x{count} {got}")


if __name__ == "__main__":
    main()
