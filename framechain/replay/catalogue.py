"""The fault catalogue of DESIGN.md (defined in :mod:`framechain.timeline.catalogue`), hops typed."""

from __future__ import annotations

from framechain.replay.replay import HopName
from framechain.timeline.catalogue import FAULT_HOP_VALUES, Fault

#: The hop each fault lives on (inverted_transform may live on either transform hop; latency also
#: on camera_to_body for a moving camera).
FAULT_HOPS: dict[Fault, HopName] = {fault: HopName(hop) for fault, hop in FAULT_HOP_VALUES.items()}

__all__ = ["FAULT_HOPS", "Fault"]
