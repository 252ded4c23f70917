"""COBS framing used by the telemetry stream: known vectors, round trip, no zero in the output."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol.cobs import cobs_decode, cobs_encode

VECTORS = [  # (data, encoded), worked by hand from the COBS rules
    (b"", b"\x01"),
    (b"\x00", b"\x01\x01"),
    (b"\x00\x00", b"\x01\x01\x01"),
    (b"\x11\x22\x00\x33", b"\x03\x11\x22\x02\x33"),
    (b"\x11\x22\x33\x44", b"\x05\x11\x22\x33\x44"),
    (b"\x11\x00\x00\x00", b"\x02\x11\x01\x01\x01"),
    (bytes(range(1, 255)), b"\xff" + bytes(range(1, 255))),
    (bytes(range(1, 255)) + b"\x00", b"\xff" + bytes(range(1, 255)) + b"\x01\x01"),
    (bytes(range(1, 256)), b"\xff" + bytes(range(1, 255)) + b"\x02\xff"),
]


@pytest.mark.parametrize("data, encoded", VECTORS)
def test_vectors(data, encoded):
    assert cobs_encode(data) == encoded
    assert cobs_decode(encoded) == data


@given(st.binary(max_size=1200))
def test_round_trip_and_no_zero(data):
    enc = cobs_encode(data)
    assert 0 not in enc
    assert len(enc) <= len(data) + 1 + len(data) // 254
    assert cobs_decode(enc) == data


@pytest.mark.parametrize(
    "bad, needle",
    [(b"\x00", "0x00 at offset 0"), (b"\x05\x11\x22", "runs past"), (b"\x03\x11\x00", "contains 0x00")],
)
def test_invalid_input_raises_value_error(bad, needle):
    with pytest.raises(ValueError, match=needle):
        cobs_decode(bad)
