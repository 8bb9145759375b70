"""The rig protocol's framing (docs/protocol.md): layout, byte order, CRC, stream resync."""

import struct
import zlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from frictionlab.realtime import protocol as P

u32 = st.integers(0, 2**32 - 1)
f32 = st.floats(-1.0, 1.0, width=32)


def test_frame_layout_is_little_endian_with_crc_over_header_and_payload():
    frame = P.command_frame(0x01020304, -0.25)
    assert frame[:2] == b"\xa5\x5a"
    assert frame[2] == P.VERSION and frame[3] == P.MSG_COMMAND
    assert frame[4:8] == bytes([4, 3, 2, 1])          # sequence number, little-endian
    assert frame[8:10] == bytes([4, 0])               # payload length 4
    assert frame[10:14] == struct.pack("<f", -0.25)   # IEEE float32, little-endian
    assert frame[14:] == struct.pack("<I", zlib.crc32(frame[2:14]))
    assert len(frame) == P.OVERHEAD + 4


def test_sensor_payload_layout():
    frame = P.encode(P.MSG_SENSOR, 7, P.sensor_payload(0.5, -0.25, 1.0, 0.125, 0x81))
    assert len(frame) == P.OVERHEAD + 17
    y, x, v, u, status = struct.unpack("<ffffB", frame[P.HEADER:P.HEADER + 17])
    assert (y, x, v, u, status) == (0.5, -0.25, 1.0, 0.125, 0x81)
    r = P.parse_sensor(P.decode(frame))
    assert r == P.SensorReading(0.5, -0.25, 1.0, 0.125, 0x81)


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(seq=u32, y=f32, x=f32, v=f32, u=f32, status=st.integers(0, 255))
def test_sensor_round_trip(seq, y, x, v, u, status):
    frame = P.decode(P.encode(P.MSG_SENSOR, seq, P.sensor_payload(y, x, v, u, status)))
    assert frame.seq == seq and frame.type == P.MSG_SENSOR
    assert P.parse_sensor(frame) == (y, x, v, u, status)


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(seq=u32, u=f32, bit=st.integers(0, 8 * (P.OVERHEAD + 4) - 1))
def test_any_single_bit_flip_is_detected(seq, u, bit):
    frame = bytearray(P.command_frame(seq, u))
    frame[bit // 8] ^= 1 << (bit % 8)
    with pytest.raises(P.FrameError):
        P.decode(bytes(frame))


@pytest.mark.parametrize("data, match", [
    (b"\xa5\x5a\x01", "short"),
    (b"\x00" * 20, "sync"),
    (P.encode(P.MSG_SAMPLE, 1)[:-1] + b"\x00" * 2, "length"),
])
def test_malformed_frames_are_rejected(data, match):
    with pytest.raises(P.FrameError, match=match):
        P.decode(data)


def test_wrong_payload_size_is_a_corrupted_message():
    frame = P.decode(P.encode(P.MSG_SENSOR, 3, b"\x00" * 5))
    with pytest.raises(P.FrameError):
        P.parse_sensor(frame)


@pytest.mark.slow
@settings(max_examples=100, deadline=None)
@given(seqs=st.lists(u32, min_size=1, max_size=8),
       noise=st.binary(max_size=30).filter(lambda b: b"\xa5" not in b),
       cuts=st.lists(st.integers(1, 40), max_size=20))
def test_stream_decoder_resynchronises_after_noise_and_corruption(seqs, noise, cuts):
    good = [P.command_frame(s, 0.5) for s in seqs]
    bad = bytearray(P.sample_frame(99))
    bad[-1] ^= 0xFF  # CRC broken
    stream = noise + good[0] + bytes(bad) + b"".join(good[1:])
    dec = P.FrameDecoder()
    out = []
    pos = 0
    for c in [*cuts, len(stream)]:  # arbitrary chunking, as a serial line delivers
        out += dec.feed(stream[pos:pos + c])
        pos += c
        if pos >= len(stream):
            break
    frames = [f for f in out if isinstance(f, P.Frame)]
    errors = [f for f in out if isinstance(f, P.FrameError)]
    # every good frame comes through, in order; the broken one is reported, not returned
    assert [f.seq for f in frames if f.type == P.MSG_COMMAND][-len(seqs):] == seqs
    assert errors
    assert not any(f.type == P.MSG_SAMPLE and f.seq == 99 for f in frames)


def test_control_messages_carry_json():
    frame = P.decode(P.control_frame(5, {"cmd": "fault", "nan": 1}))
    assert frame.type == P.MSG_CONTROL and P.parse_control(frame) == {"cmd": "fault", "nan": 1}
    with pytest.raises(P.FrameError):
        P.parse_control(P.decode(P.encode(P.MSG_CONTROL, 1, b"[1]")))


def test_noise_resembling_a_header_does_not_hold_up_the_stream():
    # sync bytes, version 1, an unknown type and a long length: rejected at once
    noise = P.SYNC + bytes([1, 0x77, 0, 0, 0, 0, 0xFF, 0x03])
    good = P.encode(P.MSG_SENSOR, 9, P.sensor_payload(0.1, 0.2, 0.3, 0.0, 0))
    out = P.FrameDecoder().feed(noise + good)
    assert isinstance(out[0], P.FrameError)
    assert [f.seq for f in out if isinstance(f, P.Frame)] == [9]
