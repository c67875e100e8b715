"""The configuration room: what a user writes (CHAIN.yaml, robot.yaml, camera calibration files),
parsed and checked through one schema (:mod:`framechain.config.schema`), every number checked for
what it can physically be (:mod:`framechain.config.plausible`), every mistake one line naming the
file, the key and the value (:class:`ConfigError`)."""

from framechain.config.chain import (
    ChainConfig,
    ChainEvidence,
    ChainFrames,
    ChainTopics,
    HopTopics,
    PoseTopic,
)
from framechain.config.chain_cameras import CalibrationSource, MarkerSpec, RigCamera
from framechain.config.errors import CalibrationError, ChainConfigError, ConfigError, RobotConfigError
from framechain.config.mount import Mount

__all__ = [
    "CalibrationError",
    "CalibrationSource",
    "ChainConfig",
    "ChainConfigError",
    "ChainEvidence",
    "ChainFrames",
    "ChainTopics",
    "ConfigError",
    "HopTopics",
    "MarkerSpec",
    "Mount",
    "PoseTopic",
    "RigCamera",
    "RobotConfigError",
]
