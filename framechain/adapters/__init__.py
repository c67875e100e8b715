"""Adapters: robot logs (MCAP, ROS 1 bag, ROS 2 bag; LeRobot via its own module) into the Timeline.

``open_log(path, chain)`` picks the reader by content and decodes only the topics the chain
needs; ``scan_log(path)`` says what a log holds from its index; ``write_log`` writes a Timeline
back with the real writers (test fixtures in every container). What a log lacks against a chain is
:mod:`framechain.suggest`'s.
"""

from framechain.adapters.api import LogAdapter, detect, open_log, register_adapter, scan_log
from framechain.adapters.errors import (
    AdapterError,
    CorruptLogError,
    EmptyLogError,
    SchemaError,
    UnsupportedLogError,
)
from framechain.adapters.formats.log_writer import CONTAINERS, canonical_order, write_log
from framechain.adapters.formats.mcap.writer import framechain_output
from framechain.adapters.lerobot.adapter import LeRobotAdapter, open_dataset, scan_dataset
from framechain.adapters.model import LoadedLog

register_adapter(LeRobotAdapter())

__all__ = [
    "CONTAINERS",
    "AdapterError",
    "CorruptLogError",
    "EmptyLogError",
    "LeRobotAdapter",
    "LoadedLog",
    "LogAdapter",
    "SchemaError",
    "UnsupportedLogError",
    "canonical_order",
    "detect",
    "framechain_output",
    "open_dataset",
    "open_log",
    "register_adapter",
    "scan_dataset",
    "scan_log",
    "write_log",
]
