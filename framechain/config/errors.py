"""Errors of the configuration room: one line naming the file, the key and what is wrong."""

from __future__ import annotations

from framechain.timeline.errors import FramechainError


class ConfigError(FramechainError):
    """A configuration file (CHAIN.yaml, robot.yaml, a calibration file) cannot be used."""


class ChainConfigError(ConfigError):
    """The chain configuration (CHAIN.yaml) is malformed or names unknown keys."""
