"""Rotation faults are fixed on the edge the camera really hangs from, in that edge's parent frame."""

from __future__ import annotations

import re

import numpy as np
from scipy.spatial.transform import Rotation

from framechain import pipeline
from framechain.analysis.model.estimates import estimate_to_json
from framechain.catalogue import Fault
from framechain.sim.scene import START_NS, InjectedFault, SceneSpec, generate
from framechain.timeline import TransformTable


def test_mast_mount_fix_names_mast_to_camera_link() -> None:
    """base_link -> mast -> camera_link -> optical: the mount fix must not give camera_link a second parent."""
    fault = InjectedFault(Fault.ROTATION_ERROR, "data", {"angle_deg": 3.0, "axis": [0, 0, 1]})
    scene = generate(SceneSpec(seed=3, duration_s=6.0, evidence="reference", faults=(fault,)))
    tf = scene.timeline.transforms
    mount = (tf.parent == "base_link") & (tf.child == "camera_link")
    i = int(np.flatnonzero(mount)[0])
    mast = TransformTable.from_rows("base_link", "mast", [START_NS], [[0.0, 0.0, 1.0]], [[0, 0, 0, 1.0]],
                                    is_static=True, source="/tf_static")
    on_mast = TransformTable.from_rows("mast", "camera_link", [START_NS], [tf.translation[i] - [0.0, 0.0, 1.0]],
                                       [tf.quat_xyzw[i]], is_static=True, source="/tf_static")
    timeline = scene.timeline.replace(transforms=TransformTable.concat([tf.take(~mount), mast, on_mast]))
    top = pipeline.run(timeline, scene.chain, bootstrap=0).attributed().findings[0]
    assert top.fault == Fault.ROTATION_ERROR
    assert abs(estimate_to_json(top.estimate)["angle_deg"] - 3.0) < 0.5
    assert "--frame-id mast --child-frame-id camera_link" in top.fix
    # The corrected mount is the true one: pitched 30 deg, no yaw (the generator's truth), 0.2 m above the mast.
    match = re.search(r'<origin xyz="([^"]+)" rpy="([^"]+)"/>', top.fix)
    assert match is not None
    np.testing.assert_allclose([float(v) for v in match.group(1).split()], [0.3, 0.0, 0.2], atol=1e-4)
    fixed = Rotation.from_euler("xyz", [float(v) for v in match.group(2).split()])
    truth = Rotation.from_euler("y", 30, degrees=True)
    assert np.rad2deg((fixed * truth.inv()).magnitude()) < 0.5
