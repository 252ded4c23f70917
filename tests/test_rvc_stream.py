"""UART-RVC stream decoder: resync, banner, chunking, bit flips, bounded memory, index gaps."""

import random

from hypothesis import given
from hypothesis import strategies as st

from protocol.rvc import MAX_BANNER_LINE, PITCH_MAX_CDEG, YAW_ROLL_MAX_CDEG, RvcDecoder, RvcFrame, RvcRaw, pack_raw

BANNER = b"%Hillcrest Labs 10003608\r\n%SW Ver 3.2.x\r\n%(c) 2017 Hillcrest Laboratories, Inc.\r\n"
DATASHEET = bytes.fromhex("AA AA DE 01 00 92 FF 25 08 8D FE EC FF D1 03 00 00 00 E7")
CONSTRUCTED = bytes.fromhex("AA AA 2A D2 04 C9 FD E2 45 0C 00 DE FF EA 03 00 00 00 C3")

int16 = st.integers(-32768, 32767)
uint8 = st.integers(0, 255)
yaw_roll = st.integers(-YAW_ROLL_MAX_CDEG, YAW_ROLL_MAX_CDEG)
pitch = st.integers(-PITCH_MAX_CDEG, PITCH_MAX_CDEG)
# frames the sensor can send: angles within its ranges (the decoder skips the others: test below)
raws = st.builds(RvcRaw, uint8, yaw_roll, pitch, yaw_roll, int16, int16, int16, uint8, uint8)
wires = raws.map(pack_raw)
# garbage without 0xAA cannot start a false header; '%' lines inside it may be counted as banner
clean_garbage = st.binary(max_size=40).map(lambda b: b.replace(b"\xaa", b"\x55"))


def decode_all(chunks):
    dec = RvcDecoder()
    out = []
    for c in chunks:
        out += dec.feed(c)
    return out, dec


def accounted(dec: RvcDecoder) -> int:
    s = dec.stats
    return 19 * s.frames + s.dropped_bytes + s.banner_bytes + dec.pending_bytes


def test_banner_then_frames():
    out, dec = decode_all([BANNER + DATASHEET + CONSTRUCTED])
    assert out == [RvcFrame.from_bytes(DATASHEET), RvcFrame.from_bytes(CONSTRUCTED)]
    s = dec.stats
    assert (s.frames, s.banner_bytes, s.dropped_bytes, s.checksum_errors) == (2, len(BANNER), 0, 0)
    assert s.bytes_in == len(BANNER) + 38


def test_banner_split_byte_by_byte_is_still_banner():
    data = BANNER + DATASHEET
    out, dec = decode_all([data[i : i + 1] for i in range(len(data))])
    assert out == [RvcFrame.from_bytes(DATASHEET)]
    assert dec.stats.banner_bytes == len(BANNER) and dec.stats.dropped_bytes == 0


def test_junk_is_counted_apart_from_banner():
    junk = b"\x01\x02%\xff\x00abc"
    out, dec = decode_all([junk + BANNER + DATASHEET])
    assert len(out) == 1
    assert dec.stats.dropped_bytes == len(junk) and dec.stats.banner_bytes == len(BANNER)


def test_unterminated_percent_line_becomes_junk_after_max_line():
    data = b"%" + b"x" * (MAX_BANNER_LINE + 10)
    out, dec = decode_all([data, DATASHEET])
    assert len(out) == 1
    assert dec.stats.banner_bytes == 0 and dec.stats.dropped_bytes == len(data)


def test_false_header_in_data_costs_one_checksum_error_and_one_byte():
    out, dec = decode_all([b"\xaa" + DATASHEET])  # AA AA AA ...: first window fails, slide by one
    assert out == [RvcFrame.from_bytes(DATASHEET)]
    assert (dec.stats.checksum_errors, dec.stats.dropped_bytes) == (1, 1)


def test_index_gaps_count_lost_frames_across_wrap():
    indices = [250, 251, 253, 254, 255, 0, 3, 4]  # missing 252, 1, 2
    stream = b"".join(pack_raw(RvcRaw(i, 0, 0, 0, 0, 0, 0)) for i in indices)
    out, dec = decode_all([stream])
    assert [f.index for f in out] == indices
    assert dec.stats.lost_frames == 3


def test_repeated_index_counts_as_a_full_wrap():
    stream = pack_raw(RvcRaw(7, 0, 0, 0, 0, 0, 0)) * 2
    _, dec = decode_all([stream])
    assert dec.stats.lost_frames == 255  # modulo-256 arithmetic cannot tell 255 lost from a repeat


@given(st.lists(st.tuples(clean_garbage, wires), max_size=12), clean_garbage, st.data())
def test_frames_not_overlapped_by_garbage_are_all_recovered_under_any_chunking(pairs, tail, data):
    """Claim: garbage free of 0xAA, placed between whole frames, never hides or alters a frame."""
    stream = b"".join(g + w for g, w in pairs) + tail
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=8)))
    chunks = [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]
    out, dec = decode_all(chunks)
    assert out == [RvcFrame.from_bytes(w) for _, w in pairs]
    garbage_len = sum(len(g) for g, _ in pairs) + len(tail)
    assert dec.stats.dropped_bytes + dec.stats.banner_bytes + dec.pending_bytes == garbage_len
    assert dec.stats.checksum_errors == 0
    assert dec.stats.bytes_in == len(stream)


@given(st.binary(max_size=300), st.data())
def test_arbitrary_bytes_same_result_under_any_chunking_and_all_bytes_accounted(stream, data):
    whole, dec1 = decode_all([stream])
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
    chunks = [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]
    parts, dec2 = decode_all(chunks)
    assert parts == whole
    assert dec1.stats == dec2.stats
    assert accounted(dec2) == len(stream) == dec2.stats.bytes_in


@given(st.lists(wires, min_size=1, max_size=6), st.binary(max_size=60), st.data())
def test_frames_with_arbitrary_garbage_keep_accounting(frames, garbage, data):
    pos = data.draw(st.integers(0, len(frames)))
    stream = b"".join(frames[:pos]) + garbage + b"".join(frames[pos:])
    out, dec = decode_all([stream])
    assert out[:pos] == [RvcFrame.from_bytes(w) for w in frames[:pos]]  # frames before garbage: intact
    assert accounted(dec) == len(stream)


def test_every_single_bit_flip_of_the_vectors_is_rejected():
    for frame in (DATASHEET, CONSTRUCTED):
        for bit in range(19 * 8):
            bad = bytearray(frame)
            bad[bit // 8] ^= 1 << (bit % 8)
            out, dec = decode_all([bytes(bad)])
            assert out == [], (frame.hex(), bit)


@given(wires, st.integers(0, 19 * 8 - 1))
def test_single_bit_flip_in_a_lone_frame_never_yields_a_message(wire, bit):
    """Bytes 2..18: the sum changes by +-2^k (k < 8), never 0 mod 256; bytes 0..1: no longer AA AA."""
    bad = bytearray(wire)
    bad[bit // 8] ^= 1 << (bit % 8)
    out, dec = decode_all([bytes(bad)])
    assert out == []
    if bit >= 16:
        assert dec.stats.checksum_errors == 1  # header intact, checksum must fail
    assert accounted(dec) == 19


def test_memory_stays_bounded_on_long_garbage():
    rng = random.Random(1234)
    alphabet = [0xAA, 0x25, 0x41, 0x0A, 0x00, 0xFF]
    dec = RvcDecoder()
    worst = 0
    for _ in range(300):
        chunk = bytes(rng.choice(alphabet) if rng.random() < 0.7 else rng.randrange(256) for _ in range(1000))
        assert isinstance(dec.feed(chunk), list)
        worst = max(worst, dec.pending_bytes)
    printable = b"%" + b"A" * 5000  # a banner-looking line that never ends
    dec.feed(printable)
    worst = max(worst, dec.pending_bytes)
    assert worst < MAX_BANNER_LINE
    assert accounted(dec) == dec.stats.bytes_in == 300_000 + len(printable)


def test_reset_drops_pending_bytes_and_index_history():
    dec = RvcDecoder()
    dec.feed(DATASHEET + CONSTRUCTED[:10])
    dec.reset()
    assert dec.pending_bytes == 0 and dec.stats.dropped_bytes == 10
    dec.feed(CONSTRUCTED)
    assert dec.stats.lost_frames == 0  # no gap across a reset
    assert accounted(dec) == dec.stats.bytes_in


def test_a_frame_whose_checksum_holds_but_whose_angles_the_sensor_cannot_send_is_counted_and_skipped():
    """A damaged frame that matched the 8-bit checksum by chance (pitch 316.74 deg was seen on a garbage-laden serial
    run): counted in range_errors, the window slides on, the frames around it are kept. The limits are inclusive."""
    good = [pack_raw(RvcRaw(i, 0, 746, 0, 0, 0, 1000)) for i in range(3)]
    bad = [pack_raw(RvcRaw(9, 0, 31674, 0, 0, 0, 1000)), pack_raw(RvcRaw(9, 0, -PITCH_MAX_CDEG - 1, 0, 0, 0, 0)),
           pack_raw(RvcRaw(9, YAW_ROLL_MAX_CDEG + 1, 0, 0, 0, 0, 0)), pack_raw(RvcRaw(9, 0, 0, -YAW_ROLL_MAX_CDEG - 1,
                                                                                     0, 0, 0))]
    edge = pack_raw(RvcRaw(3, -YAW_ROLL_MAX_CDEG, PITCH_MAX_CDEG, YAW_ROLL_MAX_CDEG, 0, 0, 0))
    out, dec = decode_all([good[0] + bad[0] + good[1] + bad[1] + bad[2] + bad[3] + good[2] + edge])
    assert out == [RvcFrame.from_bytes(f) for f in (*good, edge)]
    assert dec.stats.range_errors == 4 and dec.stats.checksum_errors == 0
    assert accounted(dec) == dec.stats.bytes_in
