"""Message decoders built from the definitions a log carries.

ROS 1 and ROS 2 messages are decoded with rosbags' typestores (generated deserialisers; the
benchmark ``benchmarks/bench_decode.py`` measured them 2.5-3x faster than mcap_ros2's dynamic
decoder on 100k TFMessage), registered from the schema text embedded in the file. Foxglove
schemas are decoded with protobuf classes built from the embedded FileDescriptorSet, or as
JSON.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from typing import Any

from framechain.adapters.formats.fast_cdr import LayoutError, parse_cdr_compressed_image, parse_cdr_image
from framechain.adapters.messages.depth import parse_ros1_image
from framechain.adapters.messages.kinds import normalize_msgtype

Decoder = Callable[[bytes | memoryview], Any]


class DecoderBuildError(Exception):
    """A schema could not be turned into a decoder (the caller names file and topic)."""


def ros_typename(name: str) -> str:
    """``pkg/Type`` or ``pkg/msg/Type`` -> ``pkg/msg/Type`` (rosbags' spelling)."""
    if "/msg/" in name or name.count("/") != 1:
        return name
    pkg, typ = name.split("/")
    return f"{pkg}/msg/{typ}"


def typestore_from_msg(name: str, text: str) -> Any:
    """A rosbags typestore holding ``name`` and every dependency in its ``MSG:`` blocks."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    try:
        store.register(get_types_from_msg(text, ros_typename(name)))
    except Exception as err:
        raise DecoderBuildError(f"cannot parse the message definition of {name} ({err})") from err
    return store


def typestore_from_idl(text: str) -> Any:
    from rosbags.typesys import Stores, get_types_from_idl, get_typestore

    store = get_typestore(Stores.EMPTY)
    sep = "=" * 80 + "\n"
    try:
        if text.startswith(f"{sep}IDL: "):
            for block in text.split(sep)[1:]:
                _, idl = block.split("\n", 1)
                store.register(get_types_from_idl(idl))
        else:
            store.register(get_types_from_idl(text))
    except Exception as err:
        raise DecoderBuildError(f"cannot parse the IDL definition ({err})") from err
    return store


def ros_decoder(store: Any, name: str, *, ros1: bool) -> Decoder:
    """Deserialiser of one type; ROS 1 images fall back to a lenient parser (trailing bytes)."""
    typename = ros_typename(name)
    if ros1:
        deserialize = store.deserialize_ros1
        if normalize_msgtype(typename) == "sensor_msgs/Image":

            def lenient(raw: bytes | memoryview) -> Any:
                try:
                    return deserialize(raw, typename)
                except Exception:
                    return parse_ros1_image(raw)

            return lenient
        return lambda raw: deserialize(raw, typename)
    deserialize_cdr = store.deserialize_cdr
    parse = _IMAGE_PARSERS.get(normalize_msgtype(typename))
    if parse is not None and [name for name, _ in store.fielddefs[typename][1]] == parse[0]:
        parse_image = parse[1]

        def image(raw: bytes | memoryview) -> Any:
            try:
                return parse_image(raw)
            except LayoutError:
                return deserialize_cdr(raw, typename)  # says what is wrong in rosbags' words

        return image
    return lambda raw: deserialize_cdr(raw, typename)


#: Image types parsed without rosbags (their pixels a view, not a copy): the fields the parser reads,
#: which the log's definition must have, and the parser.
_IMAGE_PARSERS: dict[str, tuple[list[str], Callable[[bytes | memoryview], Any]]] = {
    "sensor_msgs/Image": (["header", "height", "width", "encoding", "is_bigendian", "step", "data"], parse_cdr_image),
    "sensor_msgs/CompressedImage": (["header", "format", "data"], parse_cdr_compressed_image),
}


def protobuf_decoder(name: str, descriptor_set: bytes) -> Decoder:
    """Protobuf class of ``name`` from a serialised FileDescriptorSet (MCAP protobuf schema)."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    try:
        fds = descriptor_pb2.FileDescriptorSet.FromString(descriptor_set)
        pool = descriptor_pool.DescriptorPool()
        pending = list(fds.file)
        added: set[str] = set()
        while pending:  # add files after their dependencies
            progress = False
            for fd in list(pending):
                if all(dep in added for dep in fd.dependency):
                    pool.Add(fd)
                    added.add(fd.name)
                    pending.remove(fd)
                    progress = True
            if not progress:
                missing = sorted({d for fd in pending for d in fd.dependency} - added)
                raise DecoderBuildError(f"protobuf schema {name}: missing dependencies {missing}")
        cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(name))
    except DecoderBuildError:
        raise
    except Exception as err:
        raise DecoderBuildError(f"protobuf schema {name} cannot be loaded ({err})") from err
    return lambda raw: cls.FromString(bytes(raw))


def json_decoder() -> Decoder:
    return lambda raw: wrap_json(json.loads(bytes(raw)))


class _Obj:
    """Attribute access over a JSON object (Foxglove JSON encoding)."""

    __slots__ = ("_d",)

    def __init__(self, d: Mapping[str, Any]) -> None:
        self._d = d

    def __getattr__(self, name: str) -> Any:
        try:
            return wrap_json(self._d[name])
        except KeyError:
            raise AttributeError(name) from None


class _JsonStamp:
    __slots__ = ("nanos", "seconds")

    def __init__(self, d: Mapping[str, Any]) -> None:
        self.seconds = int(d.get("sec", 0))
        self.nanos = int(d.get("nsec", 0))


def wrap_json(value: Any) -> Any:
    """JSON values with attribute access; ``{sec, nsec}`` become protobuf-like timestamps."""
    if isinstance(value, dict):
        if set(value) <= {"sec", "nsec"} and value:
            return _JsonStamp(value)
        return _Obj(value)
    if isinstance(value, list):
        return [wrap_json(v) for v in value]
    return value
