"""Adapters: robot logs (MCAP, ROS 1 bag, ROS 2 bag; LeRobot via its own module) into the Timeline.

``open_log(path, chain)`` picks the reader by content and decodes only the topics the chain
needs; ``scan_log(path)`` says what a log holds from its index; ``write_log`` writes a Timeline
back with the real writers (test fixtures in every container); ``suggest_chain`` proposes a
chain configuration from what a log holds.
"""

from framechain.adapters.api import LogAdapter, detect, open_log, register_adapter, scan_log
from framechain.adapters.errors import (
    AdapterError,
    CorruptLogError,
    EmptyLogError,
    SchemaError,
    UnsupportedLogError,
)
from framechain.adapters.formats.mcap.export import framechain_output
from framechain.adapters.formats.writer import CONTAINERS, canonical_order, write_log
from framechain.adapters.lerobot.reader import LeRobotAdapter, open_dataset, scan_dataset
from framechain.adapters.lerobot.skeleton import GeneratedRobot, dataset_needs, generated_robot
from framechain.adapters.model import LoadedLog, LogInfo, TopicInfo
from framechain.adapters.suggest.chain import SuggestedChain, as_suggested, evidence_roles, suggest, suggest_chain
from framechain.adapters.suggest.consistency import calibration_disagreements, frame_id_disagreements
from framechain.adapters.suggest.explain import why_nothing_replayed
from framechain.adapters.suggest.facts import chain_files_beside
from framechain.adapters.suggest.frame_tree import EdgeInfo, frame_tree
from framechain.adapters.suggest.needs import ChainNeed, NeedStatus, chain_needs
from framechain.adapters.suggest.typos import MissingTopic, did_you_mean, missing_topics, or_list

register_adapter(LeRobotAdapter())

__all__ = [
    "CONTAINERS",
    "AdapterError",
    "ChainNeed",
    "CorruptLogError",
    "EdgeInfo",
    "EmptyLogError",
    "GeneratedRobot",
    "LeRobotAdapter",
    "LoadedLog",
    "LogAdapter",
    "LogInfo",
    "MissingTopic",
    "NeedStatus",
    "SchemaError",
    "SuggestedChain",
    "TopicInfo",
    "UnsupportedLogError",
    "as_suggested",
    "calibration_disagreements",
    "canonical_order",
    "chain_files_beside",
    "chain_needs",
    "dataset_needs",
    "detect",
    "did_you_mean",
    "evidence_roles",
    "frame_id_disagreements",
    "frame_tree",
    "framechain_output",
    "generated_robot",
    "missing_topics",
    "open_dataset",
    "open_log",
    "or_list",
    "register_adapter",
    "scan_dataset",
    "scan_log",
    "suggest",
    "suggest_chain",
    "why_nothing_replayed",
    "write_log",
]
