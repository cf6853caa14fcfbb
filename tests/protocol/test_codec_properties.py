"""Property tests of the compiled codecs and E2E protection, with cantools as the oracle.

Every property runs >= 1000 examples for every message type of the DBC: one message of each
layout (LEG_STATE_1..6 are one type: the same signals, ids and E2E data ids apart).
`test_each_message_is_its_types_layout_with_its_own_id` proves the grouping, and checks
every message's own id and E2E data id frame by frame."""

import math

import can
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol import e2e
from protocol.codec import CODECS, EncodeStatus, FrameDecoder
from protocol.dbc import load_database
from protocol.e2e import RxStatus

DB = load_database()
# per message type and property (x 20-30 types); the fuzz test adds a million random frames
EXAMPLES = settings(max_examples=250)
ALL = sorted(CODECS)


def _layout(codec) -> tuple:
    return codec.dlc, codec.e2e, tuple((s.name, s.start, s.length, s.signed, s.scale, s.offset, s.unit, s.minimum,
                                        s.maximum) for s in codec.signals)


# the first message (by name) of each layout: the message types the properties run on
TYPES = sorted({_layout(CODECS[n]): n for n in reversed(ALL)}.values())
PROTECTED = [n for n in TYPES if CODECS[n].e2e]


def payload_signals(codec):
    return codec.signals[2:] if codec.e2e else codec.signals


def si_values(codec, physical):
    """A values array with each payload signal at its physical value (DBC units) in SI."""
    v = codec.new_values()
    for s, x in zip(payload_signals(codec), physical):
        v[codec.index[s.name]] = x * s.to_si
    return v


def raw_grid_values(codec):
    """SI values that sit exactly on the raw grid, within the DBC range."""
    def build(raws):
        return si_values(codec, [raw * s.scale + s.offset for s, raw in zip(payload_signals(codec), raws)])
    return st.tuples(*(st.integers(s.raw_min, s.raw_max) for s in payload_signals(codec))).map(build)


def any_in_range_values(codec):
    """Arbitrary SI floats within the DBC range (between grid points)."""
    def build(xs):
        return si_values(codec, xs)
    return st.tuples(*(st.floats(s.raw_min * s.scale + s.offset, s.raw_max * s.scale + s.offset,
                                 allow_nan=False) for s in payload_signals(codec))).map(build)


@pytest.mark.parametrize("name", TYPES)
def test_roundtrip_within_half_an_lsb(name):
    codec = CODECS[name]

    @EXAMPLES
    @given(values=any_in_range_values(codec))
    def check(values):
        buf = codec.new_buffer()
        assert codec.encode_into(values, buf) is EncodeStatus.OK
        out = codec.new_values()
        codec.decode_into(buf, out)
        for s in payload_signals(codec):
            i = codec.index[s.name]
            assert abs(out[i] - values[i]) <= 0.5 * s.resolution_si * (1 + 1e-9), s.name

    check()


def beyond_range_values(codec):
    """Arbitrary SI floats up to twice each signal's range beyond either end (saturating)."""
    def build(xs):
        return si_values(codec, xs)
    spans = [(s.raw_min * s.scale + s.offset, s.raw_max * s.scale + s.offset) for s in payload_signals(codec)]
    return st.tuples(*(st.floats(lo - 2 * (hi - lo) - 1, hi + 2 * (hi - lo) + 1, allow_nan=False)
                       for lo, hi in spans)).map(build)


@pytest.mark.parametrize("name", TYPES)
def test_quantize_is_what_the_frame_decodes_to(name):
    """The in-process wire (`quantize_into`) equals encoding and decoding, bit for bit,
    saturation included; a value not finite leaves the last result."""
    codec = CODECS[name]

    @EXAMPLES
    @given(values=beyond_range_values(codec))
    def check(values):
        buf, wire, quantized = codec.new_buffer(), codec.new_values(), codec.new_values()
        codec.encode_into(values, buf)
        codec.decode_into(buf, wire)
        assert codec.quantize_into(values, quantized)
        for s in payload_signals(codec):
            i = codec.index[s.name]
            assert quantized[i] == wire[i], s.name
        before = quantized.copy()
        values[codec.index[payload_signals(codec)[-1].name]] = math.nan
        assert not codec.quantize_into(values, quantized)
        assert np.array_equal(quantized, before)

    check()


@pytest.mark.parametrize("name", TYPES)
def test_decode_equals_cantools_for_any_bytes(name):
    codec, message = CODECS[name], DB.get_message_by_name(name)

    @EXAMPLES
    @given(data=st.binary(min_size=codec.dlc, max_size=codec.dlc))
    def check(data):
        expected = message.decode(data, decode_choices=False, scaling=True)
        out_dbc, out_si = codec.new_values(), codec.new_values()
        codec.decode_dbc_units_into(data, out_dbc)
        codec.decode_into(data, out_si)
        for s in codec.signals:
            i = codec.index[s.name]
            assert out_dbc[i] == expected[s.name], s.name          # exactly cantools
            assert math.isclose(out_si[i], expected[s.name] * s.to_si, rel_tol=1e-12, abs_tol=1e-15)

    check()


@pytest.mark.parametrize("name", TYPES)
def test_encode_equals_cantools(name):
    codec, message = CODECS[name], DB.get_message_by_name(name)

    @EXAMPLES
    @given(values=raw_grid_values(codec))
    def check(values):
        buf = codec.new_buffer()
        assert codec.encode_into(values, buf) is EncodeStatus.OK
        physical = {s.name: values[codec.index[s.name]] / s.to_si for s in payload_signals(codec)}
        if codec.e2e:   # cantools knows no E2E: give it the CRC and counter we computed
            physical |= {"E2E_CRC": buf[0], "E2E_COUNTER": buf[1] & 0x0F}
        assert message.encode(physical, scaling=True, strict=True) == bytes(buf)

    check()


@pytest.mark.parametrize("name", PROTECTED)
def test_every_single_bit_flip_is_detected(name):
    codec = CODECS[name]

    @EXAMPLES
    @given(values=raw_grid_values(codec), sends=st.integers(1, 30))
    def check(values, sends):
        buf, values = codec.new_buffer(), values.tolist()      # as the loop sends: Python floats
        for _ in range(sends):
            codec.encode_into(values, buf)
        assert e2e.crc_ok(buf, codec.data_id, codec.dlc)
        decoder = FrameDecoder([name])        # a rejected frame changes nothing but the counts
        for bit in range(8 * codec.dlc):
            flipped = bytearray(buf)
            flipped[bit // 8] ^= 1 << (bit % 8)
            assert decoder.receive(codec.frame_id, flipped) is RxStatus.CRC_ERROR, bit
            assert not decoder.fresh[0] and decoder.counts[0, RxStatus.CRC_ERROR] == bit + 1

    check()


def test_each_message_is_its_types_layout_with_its_own_id():
    """The grouping into types is sound (same signals as its type's message), and each
    message's own frames carry its id and E2E data id: its receiver takes them, another
    message's receiver of the same type rejects them (CRC over the other data id)."""
    types = {_layout(CODECS[n]): n for n in TYPES}
    for name in ALL:
        codec, twin = CODECS[name], CODECS[types[_layout(CODECS[name])]]
        assert codec.signals == twin.signals and codec.dlc == twin.dlc
        message = DB.get_message_by_name(name)
        assert codec.frame_id == message.frame_id and codec.schedule.e2e_data_id == codec.data_id
        if not codec.e2e:
            continue
        assert codec.data_id == int(message.dbc.attributes["E2EDataID"].value)
        buf = codec.new_buffer()
        for _ in range(3):
            codec.encode_into(codec.new_values(), buf)
            assert FrameDecoder([name]).receive(codec.frame_id, buf) is RxStatus.OK
            if twin.name != name:
                assert twin.data_id != codec.data_id
                assert FrameDecoder([twin.name]).receive(twin.frame_id, buf) is RxStatus.CRC_ERROR


@pytest.mark.parametrize("name", [n for n in ALL if CODECS[n].e2e])
def test_counter_wraps_around_without_errors(name):
    codec = CODECS[name]
    decoder = FrameDecoder([name], max_delta_counter=1)
    values, buf = codec.new_values(), codec.new_buffer()
    seen = []
    for _ in range(4 * e2e.COUNTER_MODULO + 3):
        codec.encode_into(values, buf)
        seen.append(buf[1] & 0x0F)
        assert decoder.receive(codec.frame_id, buf) is RxStatus.OK
    assert seen[:16] == [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 0, 1]   # 15 is never sent
    assert decoder.counts[0, RxStatus.OK] == len(seen) and decoder.lost[0] == 0


@pytest.mark.parametrize("name", PROTECTED)
def test_repeated_and_skipped_counters_are_classified(name):
    codec = CODECS[name]

    @EXAMPLES
    @given(steps=st.lists(st.integers(0, 20), min_size=1, max_size=12), max_delta=st.integers(1, 5),
           values=raw_grid_values(codec))
    def check(steps, max_delta, values):
        decoder = FrameDecoder([name], max_delta_counter=max_delta)
        buf, values = codec.new_buffer(), values.tolist()
        codec.encode_into(values, buf)
        assert decoder.receive(codec.frame_id, buf) is RxStatus.OK          # first frame: initial OK
        for step in steps:   # the sender sends `step` frames, only the last one arrives
            for _ in range(step):
                codec.encode_into(values, buf)
            delta = step % e2e.COUNTER_MODULO
            expected = (RxStatus.REPEATED if delta == 0 else
                        RxStatus.OK if delta <= max_delta else RxStatus.WRONG_SEQUENCE)
            before = decoder.values[name].copy()
            assert decoder.receive(codec.frame_id, buf) is expected, (step, max_delta)
            if expected is not RxStatus.OK:
                assert np.array_equal(decoder.values[name], before, equal_nan=True)

    check()


@pytest.mark.parametrize("name", TYPES)
def test_random_frames_never_raise(name):
    codec = CODECS[name]

    @EXAMPLES
    @given(data=st.binary(min_size=0, max_size=64), frames=st.integers(1, 3))
    def check(data, frames):
        decoder = FrameDecoder()
        for _ in range(frames):
            status = decoder.receive(codec.frame_id, data)
            assert isinstance(status, RxStatus)
            if len(data) != codec.dlc:
                assert status is RxStatus.BAD_LENGTH
        assert np.all(np.isfinite(decoder.values[name]))
        assert decoder.counts.sum() == frames

    check()


@EXAMPLES
@given(frame_id=st.integers(0, 0x1FFFFFFF), data=st.binary(max_size=64), extended=st.booleans(),
       remote=st.booleans(), error=st.booleans())
def test_unknown_ids_and_odd_frames_never_raise(frame_id, data, extended, remote, error):
    decoder = FrameDecoder()
    msg = can.Message(arbitration_id=frame_id, data=data, is_extended_id=extended, is_remote_frame=remote,
                      is_error_frame=error, is_fd=len(data) > 8, check=False)
    status = decoder.receive_message(msg)
    assert isinstance(status, RxStatus)
    known = frame_id in {c.frame_id for c in CODECS.values()}
    if extended or remote or error or len(data) > 8 or not known:
        assert status is RxStatus.UNKNOWN_ID and decoder.unknown_frames == 1


@pytest.mark.parametrize("name", ["VALVE_CMD_1", "LEG_STATE_3", "HOST_WAYPOINT_POS"])
def test_out_of_range_saturates_and_non_finite_rejects(name):
    codec = CODECS[name]
    buf = codec.new_buffer()
    values = codec.new_values()
    s = payload_signals(codec)[-1]
    values[codec.index[s.name]] = (s.maximum + 10 * abs(s.maximum) + 1) * s.to_si
    assert codec.encode_into(values, buf) is EncodeStatus.SATURATED
    out = codec.new_values()
    codec.decode_into(buf, out)
    assert out[codec.index[s.name]] == pytest.approx(s.raw_max * s.scale * s.to_si)
    before = bytes(buf)
    for bad in (math.nan, math.inf, -math.inf):
        values[codec.index[s.name]] = bad
        assert codec.encode_into(values, buf) is EncodeStatus.REJECTED
        assert bytes(buf) == before           # nothing written, alive counter not advanced


def test_encode_refuses_a_short_buffer():
    codec = CODECS["LEG_STATE_1"]
    with pytest.raises(ValueError, match="LEG_STATE_1"):
        codec.encode_into(codec.new_values(), bytearray(codec.dlc - 1))


def test_spool_setpoint_scaling_is_cia408():
    codec = CODECS["VALVE_CMD_1"]
    values, buf = codec.new_values(), codec.new_buffer()
    values[codec.index["SPOOL_SETPOINT"]] = 1.0          # SI: fraction of full valve input
    codec.encode_into(values, buf)
    assert int.from_bytes(buf[2:4], "little", signed=True) == 16384
    values[codec.index["SPOOL_SETPOINT"]] = -0.5
    codec.encode_into(values, buf)
    assert int.from_bytes(buf[2:4], "little", signed=True) == -8192


def test_missing_frames_become_no_new_data():
    decoder = FrameDecoder()
    names = [f"LEG_STATE_{n}" for n in range(1, 7)]
    expected = decoder.expected_mask(names)
    bufs = {n: CODECS[n].new_buffer() for n in names}
    for cycle in range(3):
        decoder.begin_cycle()
        for n in names[: 6 - cycle]:                     # one more leg silent each cycle
            CODECS[n].encode_into(CODECS[n].new_values(), bufs[n])
            assert decoder.receive(CODECS[n].frame_id, bufs[n]) is RxStatus.OK
        assert decoder.end_cycle(expected) == cycle
    slots = [decoder.slot[n] for n in names]
    assert decoder.counts[slots, RxStatus.NO_NEW_DATA].tolist() == [0, 0, 0, 0, 1, 2]
    assert decoder.last_status[slots[-1]] == RxStatus.NO_NEW_DATA


@given(sent_before=st.integers(1, 40), sent_after=st.integers(1, 3))
@settings(max_examples=60, deadline=None)
def test_a_restarted_sender_is_taken_afresh_and_only_its_messages(sent_before, sent_after):
    """After `restart_sender`, the new process's first frame (counter from 1 again) is OK,
    whatever the old one had reached; another node's counters are still checked."""
    ack, leg = CODECS["CTRL_ACK"], CODECS["LEG_STATE_1"]
    decoder = FrameDecoder(["CTRL_ACK", "LEG_STATE_1"])
    old, leg_buf = ack.new_buffer(), leg.new_buffer()
    ack_values, leg_values = ack.new_values(), leg.new_values()
    for _ in range(sent_before):
        ack.encode_into(ack_values, old)
        assert decoder.receive(ack.frame_id, old) is RxStatus.OK
    leg.encode_into(leg_values, leg_buf)
    assert decoder.receive(leg.frame_id, leg_buf) is RxStatus.OK
    decoder.restart_sender(ack.schedule.sender)
    new = ack.new_buffer()                                  # the restarted process's own buffer
    for _ in range(sent_after):
        ack.encode_into(ack_values, new)
    assert decoder.receive(ack.frame_id, new) is RxStatus.OK
    assert decoder.receive(leg.frame_id, leg_buf) is RxStatus.REPEATED      # not the controller's
