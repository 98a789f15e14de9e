"""The protocol's conformance vectors, checked without riprs's own encoder.

``crates/rip-protocol/vectors.toml`` is what any other implementation of the serial protocol
(a MATLAB host, another firmware) is tested against, and the Rust crate runs it against its
own encoder. Here every frame is checked from docs/protocol.md's layout alone: the sync bytes,
the length byte, the CRC-16/CCITT-FALSE (``binascii.crc_hqx`` with initial value 0xFFFF), and
the telemetry record's fields unpacked with ``struct`` in the documented order.
"""

from __future__ import annotations

import binascii
import struct
import sys
from pathlib import Path

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

VECTORS = Path(__file__).resolve().parents[1] / "crates" / "rip-protocol" / "vectors.toml"
HEADER_LEN = 7
TRAILER_LEN = 2


def _frames() -> list[dict]:
    return tomllib.loads(VECTORS.read_text())["frame"]


@pytest.mark.parametrize("vector", _frames(), ids=lambda v: v["name"])
def test_each_frame_has_its_sync_length_and_crc(vector: dict) -> None:
    frame = bytes.fromhex(vector["hex"])
    assert frame[:2] == b"\xa5\x5a"
    n = frame[6]
    assert len(frame) == HEADER_LEN + n + TRAILER_LEN
    assert n <= 32, "the payload limit, MAX_PAYLOAD"
    (crc,) = struct.unpack_from("<H", frame, HEADER_LEN + n)
    assert crc == binascii.crc_hqx(frame[2 : HEADER_LEN + n], 0xFFFF)
    assert struct.unpack_from("<H", frame, 4)[0] == vector["seq"]


def test_the_telemetry_record_unpacks_in_the_documented_order() -> None:
    (vector,) = [v for v in _frames() if v["type"] == "telemetry"]
    frame = bytes.fromhex(vector["hex"])
    assert (frame[2], frame[3]) == (2, 0x21)
    payload = frame[HEADER_LEN:-TRAILER_LEN]
    fields = (
        "step device_time_us arm_counts pendulum_counts applied_mv status onboard "
        "step_cycles overruns fallbacks"
    ).split()
    layout = "<IIiihBBIHH"
    assert struct.calcsize(layout) == len(payload) == 28
    assert dict(zip(fields, struct.unpack(layout, payload), strict=True)) == {
        f: vector[f] for f in fields
    }
