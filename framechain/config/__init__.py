"""The configuration room: what a user writes (CHAIN.yaml, robot.yaml, camera calibration files),
parsed and checked, every mistake one line naming the file, the key and the value."""

from framechain.config.chain import (
    CalibrationSource,
    ChainConfig,
    ChainEvidence,
    ChainFrames,
    ChainTopics,
    HopTopics,
    MarkerSpec,
    MountEdge,
    PoseTopic,
)
from framechain.config.errors import ChainConfigError, ConfigError

__all__ = [
    "CalibrationSource",
    "ChainConfig",
    "ChainConfigError",
    "ChainEvidence",
    "ChainFrames",
    "ChainTopics",
    "ConfigError",
    "HopTopics",
    "MarkerSpec",
    "MountEdge",
    "PoseTopic",
]
