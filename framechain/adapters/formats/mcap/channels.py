"""An MCAP channel and what its schema lets framechain decode: ROS 2 (cdr with a ros2msg or ros2idl schema),
ROS 1 (ros1msg), Foxglove protobuf, or JSON (which needs no schema)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from framechain.adapters.formats.decoders import (
    Decoder,
    DecoderBuildError,
    json_decoder,
    protobuf_decoder,
    ros_decoder,
    ros_typename,
    typestore_from_idl,
    typestore_from_msg,
)

__all__ = ["Channel", "RosType", "channel_decoder", "undecodable"]

#: A ROS channel's typestore, its type name (rosbags' spelling) and whether it is ROS 1.
RosType = tuple[Any, str, bool]


@dataclass
class Channel:
    id: int
    topic: str
    encoding: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes


#: (message encoding, schema encoding) pairs with a decoder; JSON needs no schema to be read.
_DECODABLE = {("cdr", "ros2msg"), ("cdr", "ros2idl"), ("ros1", "ros1msg"), ("protobuf", "protobuf")}


def undecodable(ch: Channel) -> str:
    """Why a channel's messages cannot be decoded ('' when they can)."""
    if ch.encoding == "json":
        return ""
    if not ch.schema_name:
        return f"no schema for message encoding {ch.encoding!r}, so the message type is unknown"
    if (ch.encoding, ch.schema_encoding) not in _DECODABLE:
        return (f"message encoding {ch.encoding!r} with schema encoding {ch.schema_encoding!r} ({ch.schema_name}) "
                "is not supported (cdr/ros2msg, cdr/ros2idl, ros1/ros1msg, protobuf or json)")
    return ""


def channel_decoder(ch: Channel) -> tuple[Decoder, RosType | None]:
    """The decoder of a channel's messages, and for a ROS channel its :data:`RosType` (the batched decoders
    need it); raises :class:`DecoderBuildError` when the channel cannot be decoded."""
    problem = undecodable(ch)
    if problem:
        raise DecoderBuildError(problem)
    text = ch.schema_data.decode("utf-8", "replace")
    ros: tuple[Any, bool] | None = None
    if ch.encoding == "cdr" and ch.schema_encoding == "ros2msg":
        ros = typestore_from_msg(ch.schema_name, text), False
    elif ch.encoding == "cdr" and ch.schema_encoding == "ros2idl":
        ros = typestore_from_idl(text), False
    elif ch.encoding == "ros1" and ch.schema_encoding == "ros1msg":
        ros = typestore_from_msg(ch.schema_name, text), True
    if ros is not None:
        store, ros1 = ros
        return ros_decoder(store, ch.schema_name, ros1=ros1), (store, ros_typename(ch.schema_name), ros1)
    if ch.encoding == "protobuf" and ch.schema_encoding == "protobuf":
        return protobuf_decoder(ch.schema_name, ch.schema_data), None
    return json_decoder(), None  # the only encoding left that undecodable lets through
