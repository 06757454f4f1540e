"""Protocol 2.0 codec: CRC golden vectors, byte stuffing, the streaming decoder, error bytes,
and the control-table conversions. Pure: no I/O."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robot.dynamixel import protocol as p
from robot.dynamixel.control_table import XL320, XL330_M288, ControlTableError, model_by_name

# Golden vectors from the ROBOTIS e-manual examples (docs/facts.md): packet without CRC,
# then the CRC bytes as sent (low byte first).
GOLDEN = [
    ("FF FF FD 00 01 03 00 01", "19 4E"),
    ("FF FF FD 00 01 07 00 02 84 00 04 00", "1D 15"),
    ("FF FF FD 00 FE 09 00 82 84 00 04 00 01 02", "CE FA"),
]


@pytest.mark.parametrize(("packet", "crc"), GOLDEN)
def test_crc_golden_vectors(packet: str, crc: str) -> None:
    value = p.crc16(bytes.fromhex(packet))
    assert bytes([value & 0xFF, value >> 8]) == bytes.fromhex(crc)


def test_builders_reproduce_the_golden_packets() -> None:
    built = [p.ping(1), p.read(1, 132, 4), p.sync_read(132, 4, [1, 2])]
    for pkt, (head, crc) in zip(built, GOLDEN, strict=True):
        assert pkt.encode() == bytes.fromhex(head + crc)


def test_stuffing_inserts_fd_and_length_and_crc_follow_it() -> None:
    pkt = p.write(1, 30, b"\xff\xff\xfd\x10")
    wire = pkt.encode()
    body = bytes([p.Instruction.WRITE]) + b"\x1e\x00" + b"\xff\xff\xfd\xfd\x10"
    assert wire[7:-2] == body
    assert int.from_bytes(wire[5:7], "little") == len(body) + 2
    assert int.from_bytes(wire[-2:], "little") == p.crc16(wire[:-2])
    assert p.decode_all(wire) == [pkt]


def test_stuffing_of_pattern_at_the_very_start_of_params() -> None:
    status = p.StatusPacket(3, 0, b"\xfd\xff\xff\xfd")
    assert p.decode_all(status.encode()) == [status]


@given(st.binary(max_size=64))
def test_stuffing_round_trip(data: bytes) -> None:
    stuffed = p.stuff(data)
    assert p.unstuff(stuffed) == data
    # every FF FF FD of the stuffed stream is followed by FD, so no header hides inside
    i = stuffed.find(b"\xff\xff\xfd")
    while i >= 0:
        assert stuffed[i + 3 : i + 4] == b"\xfd"
        i = stuffed.find(b"\xff\xff\xfd", i + 1)
    assert p.HEADER not in stuffed


# Bytes that look like protocol fragments, to make the noise adversarial.
_noise_byte = st.one_of(st.sampled_from([0xFF, 0xFD, 0x00, 0x01, 0x55, 0x03]), st.integers(0, 255))
_noise = st.lists(_noise_byte, max_size=24).map(bytes)
_params = st.binary(max_size=12) | st.lists(st.sampled_from([0xFF, 0xFD, 0x00]), max_size=12).map(
    bytes
)
_instruction = st.builds(
    p.InstructionPacket,
    st.integers(0, 252) | st.just(p.BROADCAST_ID),
    st.sampled_from([i for i in p.Instruction if i != p.Instruction.STATUS]),
    _params,
)
_status = st.builds(p.StatusPacket, st.integers(0, 252), st.integers(0, 255), _params)


@given(st.lists(st.tuples(_noise, _instruction | _status), max_size=6), _noise, st.data())
@settings(max_examples=300, deadline=None)
def test_decoder_finds_exactly_the_packets_in_noise(
    pairs: list[tuple[bytes, p.Packet]], tail: bytes, data: st.DataObject
) -> None:
    stream = b"".join(noise + pkt.encode() for noise, pkt in pairs) + tail
    # feed in random chunks: packets arrive split anywhere
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=8)))
    decoder = p.Decoder()
    found: list[p.Item] = []
    for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        found += decoder.feed(stream[a:b])
    packets = [x for x in found if not isinstance(x, p.CorruptFrame)]
    assert packets == [pkt for _, pkt in pairs]


def test_decoder_handles_echo_then_reply() -> None:
    request = p.read(1, 37, 2)
    reply = p.StatusPacket(1, 0, b"\x00\x02")
    items = p.Decoder().feed(request.encode() + reply.encode())
    assert items == [request, reply]


def test_decoder_reports_crc_errors_and_resynchronises() -> None:
    good = p.StatusPacket(2, 0, b"\x01\x02").encode()
    bad = bytearray(good)
    bad[-1] ^= 0x40
    items = p.Decoder().feed(bytes(bad) + good)
    assert isinstance(items[0], p.CorruptFrame) and items[0].reason == "crc"
    assert items[-1] == p.StatusPacket(2, 0, b"\x01\x02")


def test_decoder_drops_a_truncated_packet_when_the_next_header_arrives() -> None:
    first = p.StatusPacket(1, 0, bytes(10)).encode()
    second = p.StatusPacket(2, 0, b"\x07").encode()
    items = p.Decoder().feed(first[:9] + second)
    assert isinstance(items[0], p.CorruptFrame) and items[0].reason == "truncated"
    assert items[1] == p.StatusPacket(2, 0, b"\x07")


def test_decoder_waits_for_partial_packets() -> None:
    wire = p.StatusPacket(4, 0, b"\x11\x22\x33").encode()
    d = p.Decoder()
    for b in wire[:-1]:
        assert d.feed(bytes([b])) == []
    assert d.feed(wire[-1:]) == [p.StatusPacket(4, 0, b"\x11\x22\x33")]
    assert d.pending == 0


def test_decoder_rejects_absurd_lengths_at_once() -> None:
    garbage = p.HEADER + b"\x01\xff\xff"  # LEN 65535 > max_length
    wire = p.ping(1).encode()
    assert p.Decoder().feed(garbage + wire) == [p.ping(1)]


@pytest.mark.parametrize(
    ("byte", "alert", "code", "text"),
    [
        (0x00, False, 0, "no error"),
        (0x01, False, 1, "result fail"),
        (0x02, False, 2, "instruction error"),
        (0x03, False, 3, "CRC error"),
        (0x04, False, 4, "data range error"),
        (0x05, False, 5, "data length error"),
        (0x06, False, 6, "data limit error"),
        (0x07, False, 7, "access error"),
        (0x80, True, 0, "hardware alert"),
        (0x87, True, 7, "access error, hardware alert"),
        (0x09, False, 9, "unknown error 9"),
    ],
)
def test_error_byte_decoding(byte: int, alert: bool, code: int, text: str) -> None:
    err = p.decode_error(byte)
    assert (err.alert, err.code, str(err)) == (alert, code, text)
    assert bool(err) == (byte != 0)
    assert p.StatusPacket(1, byte).alert == alert


def test_param_builders_and_parsers_agree() -> None:
    sw = p.sync_write(30, 2, {1: b"\x00\x02", 2: b"\xff\x03"})
    assert p.parse_sync_write(sw.params) == (30, 2, {1: b"\x00\x02", 2: b"\xff\x03"})
    sr = p.sync_read(37, 4, [1, 2, 3])
    assert p.parse_sync_read(sr.params) == (37, 4, [1, 2, 3])
    br = p.bulk_read([(1, 37, 2), (2, 50, 1)])
    assert p.parse_bulk_read(br.params) == [(1, 37, 2), (2, 50, 1)]
    assert p.parse_read(p.read(5, 50, 1).params) == (50, 1)
    assert p.parse_write(p.write(5, 24, b"\x01").params) == (24, b"\x01")
    assert p.parse_ping_reply(b"\x5e\x01\x1d") == (350, 29)
    assert p.reboot(3).instruction == p.Instruction.REBOOT


@pytest.mark.parametrize(
    "make",
    [
        lambda: p.ping(253),
        lambda: p.sync_read(0, 1, []),
        lambda: p.sync_write(0, 2, {1: b"\x00"}),
        lambda: p.bulk_read([(1, 0, 1), (1, 2, 1)]),
        lambda: p.read(1, 70000, 1),
        lambda: p.parse_sync_write(b"\x1e\x00\x02\x00\x01\x00"),
    ],
)
def test_bad_input_gives_one_line_protocol_errors(make) -> None:
    with pytest.raises(p.ProtocolError) as info:
        make().encode()
    assert "\n" not in str(info.value)


# ---- control tables -------------------------------------------------------------------------
def test_xl320_table_matches_the_architecture_page() -> None:
    expect = {
        "torque_enable": (24, 1),
        "goal_position": (30, 2),
        "moving_speed": (32, 2),
        "torque_limit": (35, 2),
        "present_position": (37, 2),
        "present_speed": (39, 2),
        "present_load": (41, 2),
        "present_voltage": (45, 1),
        "present_temperature": (46, 1),
        "moving": (49, 1),
        "hardware_error_status": (50, 1),
        "return_delay_time": (5, 1),
    }
    for name, (address, size) in expect.items():
        r = XL320.reg(name)
        assert (r.address, r.size) == (address, size)
    assert XL320.reg("return_delay_time").eeprom and not XL320.reg("goal_position").eeprom
    assert XL320.reg("present_position").access == "R"


def test_xl320_conversions() -> None:
    assert XL320.steps_to_rad(np.array([512]))[0] == 0.0
    assert math.isclose(
        XL320.steps_to_rad(np.array([1023]))[0], math.radians(150) * 1.0, rel_tol=2e-3
    )
    assert XL320.rad_to_steps(np.array([0.0, 10.0, -10.0])).tolist() == [512, 1023, 0]
    q = np.linspace(-2.5, 2.5, 11)
    assert np.all(np.abs(XL320.steps_to_rad(XL320.rad_to_steps(q)) - q) <= XL320.rad_per_step)
    # bit 10 is the direction: 1024 + 100 = 100 units clockwise (negative)
    assert XL320.load_to_fraction(np.array([100, 1124])).tolist() == pytest.approx([0.1, -0.1])
    assert XL320.fraction_to_load(np.array([-0.1, 2.0])).tolist() == [1124, 1023]
    assert XL320.speed_to_rad_s(np.array([1023]))[0] == pytest.approx(11.89, abs=0.01)
    assert XL320.voltage_to_volts(np.array([74]))[0] == pytest.approx(7.4)
    assert XL320.decode_hardware_error(0b101) == ["overload", "input voltage"]


def test_xl330_conversions_and_block_extraction() -> None:
    assert XL330_M288.steps_to_rad(np.array([2048 + 1024]))[0] == pytest.approx(math.pi / 2)
    reg = XL330_M288.reg("present_velocity")
    assert reg.decode(reg.encode(-5)) == -5
    address, length = XL330_M288.block(["velocity", "position"])
    assert (address, length) == (128, 8)
    data = reg.encode(-10) + XL330_M288.reg("position").encode(3000)
    assert XL330_M288.extract("position", address, data) == 3000
    assert XL330_M288.speed_to_rad_s(np.array([-10]))[0] < 0
    assert XL330_M288.decode_hardware_error(1 << 5) == ["overload"]
    with pytest.raises(ControlTableError, match="no register"):
        XL330_M288.reg("punch")


def test_model_lookup() -> None:
    assert model_by_name("xl320") is XL320
    assert model_by_name("XL330-M288-T") is XL330_M288
    assert model_by_name(1200) is XL330_M288
    with pytest.raises(ControlTableError, match="unknown Dynamixel model"):
        model_by_name("AX-12")
