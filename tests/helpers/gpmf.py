"""GoPro GPMF telemetry from an MP4's data track, for the real-data tests (the product reads no GPMF).

A GoPro MP4 carries its sensors in a data track (handler "GoPro MET", sample format ``gpmd``): one
MP4 sample (a packet, about 1 s) per flush, each a GPMF payload. GPMF is key-length-value, big
endian, 32-bit aligned: a 4-character key, a type character (0: nested KLV), a struct size (bytes
per sample), a repeat (samples), then ``size * repeat`` bytes padded to 4. A payload nests
``DEVC`` (a device) > ``STRM`` (a stream); inside a stream the properties come before the data
they apply to: ``SCAL`` (a divisor, one or one per channel), ``STNM`` (name), ``SIUN`` (units),
``TSMP`` (samples so far), ``STMP`` (the packet's first sample in microseconds, newer cameras),
``ORIN``/``ORIO``/``MTRX`` (axis order of the channels, of the output, and the matrix between).

Samples carry no stamps. Packet ``k`` spans its MP4 sample's time ``[pts_k, pts_k + duration_k)``
and its ``n_k`` samples spread evenly over it (``clock="mp4"``); with ``clock="stmp"`` the packets
start at their ``STMP`` instead and end where the next one starts. The last packet's MP4 duration
is not its samples' (karma.mp4 says 1.001 s for 28 gyro samples in a 12.08 s clip): its samples
keep the median spacing of the others.

Axis letters follow GoPro's picture of the camera's IMU axes (gpmf-parser docs): Z up through the
shutter button, Y out of the back (the screen side; the lens looks along -Y), X to the left as seen
from behind. The Hero5 names its gyro stream "Gyroscope (z,x,y)" and has no ``ORIN``; the MAX gives
``ORIN`` "XzY" (a lower-case letter is that axis negated).

The MAX's ``CORI`` (camera orientation since the start) and ``IORI`` (the stabilised image's
orientation relative to the body) are quaternions w, x, y, z over ``SCAL``, once per frame.
:func:`camera_orientation` reads ``CORI`` as the conjugate, ``R_start_cam`` in the optical frame
(x right, y down, z forward): so read, the integrated gyro reproduces it to 0.005 deg per frame.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import av
import numpy as np

from framechain.arrays import FloatArray, IntArray

Clock = Literal["mp4", "stmp"]

#: GPMF type characters with a fixed numeric layout (big endian).
_NUMERIC = {"b": ">i1", "B": ">u1", "s": ">i2", "S": ">u2", "l": ">i4", "L": ">u4", "f": ">f4", "d": ">f8",
            "j": ">i8", "J": ">u8"}
#: Properties of a stream that describe the data after them (sticky within the stream).
_PROPERTIES = {"SCAL", "STNM", "SIUN", "UNIT", "TSMP", "STMP", "ORIN", "ORIO", "MTRX", "TMPC", "TICK", "EMPT",
               "TYPE", "VPTS", "RMRK"}


@dataclass(frozen=True)
class Klv:
    """One GPMF key-length-value entry: ``children`` for nested entries (``type`` ""), else raw ``data``."""

    key: str
    type: str
    struct_size: int
    repeat: int
    data: bytes
    children: tuple[Klv, ...] = ()

    def numbers(self) -> FloatArray:
        """The samples as numbers, ``(repeat, struct_size // item size)`` (plain numeric types only)."""
        if self.type not in _NUMERIC:
            raise ValueError(f"GPMF {self.key!r}: type {self.type!r} is not a plain number (a TYPE struct?)")
        dtype = np.dtype(_NUMERIC[self.type])
        out: FloatArray = np.frombuffer(self.data, dtype=dtype).astype(np.float64).reshape(self.repeat, -1)
        return out

    def text(self) -> str:
        return self.data.decode("latin-1").rstrip("\x00")


def parse_klv(payload: bytes) -> tuple[Klv, ...]:
    """The KLV entries of a GPMF payload (nested ones parsed into ``children``)."""
    out: list[Klv] = []
    at = 0
    while at + 8 <= len(payload):
        key = payload[at:at + 4].decode("latin-1")
        type_char = "" if payload[at + 4] == 0 else chr(payload[at + 4])
        size, repeat = payload[at + 5], int.from_bytes(payload[at + 6:at + 8], "big")
        length = size * repeat
        if at + 8 + length > len(payload):
            raise ValueError(f"GPMF entry {key!r} at byte {at}: {length} bytes announced, {len(payload) - at - 8} left")
        data = payload[at + 8:at + 8 + length]
        out.append(Klv(key, type_char, size, repeat, data, parse_klv(data) if type_char == "" else ()))
        at += 8 + (length + 3) // 4 * 4
    return tuple(out)


@dataclass(frozen=True)
class Packet:
    """One MP4 sample of the GPMF track: its span on the video's clock and its parsed payload."""

    start_s: float
    duration_s: float
    entries: tuple[Klv, ...]


def read_packets(path: str | Path) -> list[Packet]:
    """The GPMF track's packets, demuxed with PyAV (the data stream whose handler is "GoPro MET")."""
    with av.open(str(path)) as container:
        streams = [s for s in container.streams if s.type == "data" and "GoPro MET" in s.metadata.get(
            "handler_name", "")]
        if not streams:
            raise ValueError(f"{path}: no GoPro MET (GPMF) data track")
        stream = streams[0]
        if stream.time_base is None:
            raise ValueError(f"{path}: the GPMF track has no time base")
        base = float(stream.time_base)
        return [Packet(p.pts * base, (p.duration or 0) * base, parse_klv(bytes(p)))
                for p in container.demux(stream) if p.size and p.pts is not None]


@dataclass(frozen=True)
class SensorStream:
    """One sensor's samples over a clip: values after ``SCAL``, times on the video's clock.

    ``axis_order`` names the channels in GoPro's camera axes (``ORIN`` when given, else the letters
    of the stream's name, "" when neither says); ``matrix`` is the stream's ``MTRX`` (output = M @
    channels), ``output_order`` its ``ORIO``. Per packet: its start (s), sample count and ``STMP`` (s,
    NaN when absent).
    """

    key: str
    device: str
    name: str
    units: str
    times_s: FloatArray  # (N,)
    values: FloatArray  # (N, C)
    axis_order: str
    output_order: str
    matrix: FloatArray | None
    packet_start_s: FloatArray
    packet_counts: IntArray
    packet_stmp_s: FloatArray
    total_samples: IntArray  # TSMP per packet

    @property
    def rate_hz(self) -> float:
        """Samples per second over the whole packets (the last, cut short by the clip's end, left out)."""
        full = slice(0, max(self.packet_counts.size - 1, 1))
        span = float(np.sum(np.diff(self.packet_start_s)[full])) if self.packet_counts.size > 1 else 0.0
        return float(self.packet_counts[full].sum() / span) if span > 0 else float("nan")


@dataclass
class _Found:
    """One stream's pieces gathered packet by packet."""

    device: str = ""
    name: str = ""
    units: str = ""
    order: str = ""
    output: str = ""
    matrix: FloatArray | None = None


def read_stream(path: str | Path, key: str, *, clock: Clock = "mp4",
                packets: list[Packet] | None = None) -> SensorStream:
    """Every sample of the stream whose data key is ``key`` (GYRO, ACCL, CORI, IORI, GRAV...), scaled."""
    packets = read_packets(path) if packets is None else packets
    found = _Found()
    chunks: list[FloatArray] = []
    stmp: list[float] = []
    tsmp: list[int] = []
    for packet in packets:
        values, props = _stream_in_packet(packet.entries, key, found)
        chunks.append(values)
        stmp.append(float(props["STMP"].numbers()[0, 0]) * 1e-6 if "STMP" in props else float("nan"))
        tsmp.append(int(props["TSMP"].numbers()[0, 0]) if "TSMP" in props else -1)
    if not any(c.size for c in chunks):
        raise ValueError(f"{path}: no {key} samples in the GPMF track")
    counts = np.array([len(c) for c in chunks], dtype=np.int64)
    starts = np.array([p.start_s for p in packets])
    durations = np.array([p.duration_s for p in packets])
    stmp_s = np.array(stmp)
    if clock == "stmp":
        if not np.isfinite(stmp_s).all():
            raise ValueError(f"{path}: {key} has no STMP in every packet")
        starts, durations = stmp_s, np.r_[np.diff(stmp_s), np.nan]
    return SensorStream(
        key=key, device=found.device, name=found.name, units=found.units,
        times_s=_spread(starts, durations, counts), values=np.concatenate([c for c in chunks if c.size]),
        axis_order=found.order, output_order=found.output, matrix=found.matrix,
        packet_start_s=starts, packet_counts=counts, packet_stmp_s=stmp_s,
        total_samples=np.array(tsmp, dtype=np.int64))


def _stream_in_packet(entries: tuple[Klv, ...], key: str, found: _Found) -> tuple[FloatArray, dict[str, Klv]]:
    """The scaled samples of ``key`` in one packet and the properties of its stream (noting names and axes)."""
    for device in (e for e in entries if e.key == "DEVC"):
        name = next((e.text() for e in device.children if e.key == "DVNM"), "")
        for stream in (e for e in device.children if e.key == "STRM"):
            data = [e for e in stream.children if e.key == key]
            if not data:
                continue
            props = {e.key: e for e in stream.children if e.key in _PROPERTIES}
            found.device, found.name = name, props["STNM"].text() if "STNM" in props else ""
            found.units = props["SIUN"].text() if "SIUN" in props else ""
            found.order = props["ORIN"].text() if "ORIN" in props else _letters(found.name)
            found.output = props["ORIO"].text() if "ORIO" in props else ""
            found.matrix = props["MTRX"].numbers().reshape(3, 3) if "MTRX" in props else None
            values = np.concatenate([d.numbers() for d in data])
            return values / _scale(props.get("SCAL"), values.shape[1]), props
    return np.zeros((0, 0)), {}


def _scale(scal: Klv | None, channels: int) -> FloatArray:
    """The divisor of each channel: one for all, or one per channel."""
    if scal is None:
        return np.ones(channels)
    out: FloatArray = np.broadcast_to(scal.numbers().ravel(), (channels,)).astype(np.float64)
    return out


def _letters(name: str) -> str:
    """Axis letters from a stream name such as "Gyroscope (z,x,y)" (upper case: named, not negated)."""
    match = re.search(r"\(([xyzXYZ]),\s*([xyzXYZ]),\s*([xyzXYZ])\)", name)
    return "".join(match.groups()).upper() if match else ""


def _spread(starts: FloatArray, durations: FloatArray, counts: IntArray) -> FloatArray:
    """Sample times: each packet's samples evenly over its span; the last packet at the others' median spacing."""
    spacing = durations / np.maximum(counts, 1)
    if counts.size > 1:
        spacing[-1] = float(np.median(spacing[:-1][counts[:-1] > 0]))
    first = np.repeat(starts, counts)
    index = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
    out: FloatArray = first + index * np.repeat(spacing, counts)
    return out


def axes_matrix(order: str) -> FloatArray:
    """The signed permutation taking channels named by ``order`` ("ZXY", "XzY") to GoPro's X, Y, Z."""
    if sorted(order.upper()) != ["X", "Y", "Z"]:
        raise ValueError(f"axis order {order!r} does not name X, Y and Z once each")
    out = np.zeros((3, 3))
    for channel, letter in enumerate(order):
        out["XYZ".index(letter.upper()), channel] = 1.0 if letter.isupper() else -1.0
    return out


def camera_orientation(cori: SensorStream) -> FloatArray:
    """``R_start_cam`` (N, 4) xyzw from a ``CORI`` stream (quaternions w, x, y, z, read as their conjugate)."""
    w, x, y, z = cori.values.T
    quat = np.stack([-x, -y, -z, w], axis=1)
    out: FloatArray = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    return out
