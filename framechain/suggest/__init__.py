"""What a log has against what a chain needs: the frame tree, the suggested chain, what is missing and the key that
supplies it, hints from files beside the log, and a robot.yaml to start from for a LeRobot dataset."""

from framechain.suggest.chain import SuggestedChain, as_suggested, evidence_roles, suggest, suggest_chain
from framechain.suggest.consistency import calibration_disagreements, frame_id_disagreements
from framechain.suggest.explain import why_nothing_replayed
from framechain.suggest.facts import chain_files_beside
from framechain.suggest.frame_tree import EdgeInfo, frame_tree
from framechain.suggest.lerobot import dataset_needs, generated_robot
from framechain.suggest.needs import ChainNeed, NeedStatus, chain_needs
from framechain.suggest.typos import MissingTopic, did_you_mean, missing_topics, or_list

__all__ = [
    "ChainNeed",
    "EdgeInfo",
    "MissingTopic",
    "NeedStatus",
    "SuggestedChain",
    "as_suggested",
    "calibration_disagreements",
    "chain_files_beside",
    "chain_needs",
    "dataset_needs",
    "did_you_mean",
    "evidence_roles",
    "frame_id_disagreements",
    "frame_tree",
    "generated_robot",
    "missing_topics",
    "or_list",
    "suggest",
    "suggest_chain",
    "why_nothing_replayed",
]
