"""Errors of the configuration room: one line naming the file, the key and what is wrong."""

from __future__ import annotations

from framechain.errors import FramechainError


class ConfigError(FramechainError):
    """A configuration file (CHAIN.yaml, robot.yaml, a calibration file) cannot be used.

    ``source`` names the file (or the mapping it came from), ``what`` the key and what is wrong with
    its value; the message is ``"source: what"``, one line.
    """

    def __init__(self, source: str, what: str) -> None:
        self.source = source
        self.what = what
        super().__init__(f"{source}: {what}" if source else what)


class ChainConfigError(ConfigError):
    """The chain configuration (CHAIN.yaml) is malformed or names unknown keys."""


class CalibrationError(ConfigError):
    """A calibration file is unreadable, incomplete or inconsistent."""


class RobotConfigError(ConfigError):
    """robot.yaml is malformed, names unknown joints or states, or leaves a unit unstated."""
