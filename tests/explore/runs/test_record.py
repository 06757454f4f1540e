"""The record decoder on damaged bytes: whatever it is given (empty, a bare ``.npy``, an array
this class does not have, any mutation of a packed or npz record, any header), it returns a
record or raises ``RecordError`` with one line, never another exception (``pytest
--hypothesis-profile fuzz`` runs the property for long, tests/conftest.py)."""

from __future__ import annotations

import io
import json
import struct
import zlib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from explore.runs.record import PACKED_MAGIC, EpisodeRecord, RecordError

SCALARS = ("episode", "module", "kind", "ball_moved", "settle_s", "duration_s")
ARRAYS = (
    "theta", "goal", "context_ball", "ball", "targets", "measured", "end_effector", "image",
    "sim_state", "context_distractor", "distractor", "start_positions",
)  # fmt: skip


def record(k: int = 0, ticks: int = 3) -> EpisodeRecord:
    """A small record (a few hundred bytes packed), its distractor known."""
    rng = np.random.default_rng(k)
    return EpisodeRecord(
        episode=k, theta=rng.uniform(-1, 1, 4), goal=rng.normal(size=2), module=1, kind="goal",
        context_ball=np.array([0.1, 0.0]), ball=np.array([np.nan, 0.1]), ball_moved=True,
        targets=rng.normal(size=(ticks, 6)), measured=rng.normal(size=(ticks, 6)),
        end_effector=rng.normal(size=(ticks, 3)),
        image=rng.integers(0, 255, (2, 2, 3), dtype=np.uint8), sim_state=rng.normal(size=3),
        settle_s=0.5, duration_s=0.01, distractor=np.array([0.2, 0.1]),
    )  # fmt: skip


def npz_bytes(rec: EpisodeRecord, **extra: object) -> bytes:
    """``rec`` as records were stored before the packed form (``np.savez_compressed``)."""
    buf = io.BytesIO()
    names = (*ARRAYS[:9], *SCALARS, "distractor")
    np.savez_compressed(buf, **({n: np.asarray(getattr(rec, n)) for n in names} | extra))
    return buf.getvalue()


def packed(head: object, body: bytes) -> bytes:
    text = json.dumps(head).encode()
    return PACKED_MAGIC + struct.pack("<I", len(text)) + text + body


def _head_and_body(rec: EpisodeRecord) -> tuple[dict, bytes]:
    data = rec.to_bytes()
    (n,) = struct.unpack_from("<I", data, 4)
    return json.loads(data[8 : 8 + n]), data[8 + n :]


def _one_line_error(data: bytes) -> str:
    with pytest.raises(RecordError) as info:
        EpisodeRecord.from_bytes(data)
    assert "\n" not in str(info.value)
    return str(info.value)


def test_both_forms_round_trip():
    rec = record(3)
    assert EpisodeRecord.from_bytes(rec.to_bytes()).equals(rec)
    assert EpisodeRecord.from_bytes(npz_bytes(rec)).equals(rec)


def _bare_npy() -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.zeros(3))
    return buf.getvalue()


def _packed_with(extra: list) -> bytes:
    head, body = _head_and_body(record())
    head["arrays"].append(extra)
    return packed(head, body)


@pytest.mark.parametrize(
    ("case", "data", "says"),
    [
        ("empty", b"", "it is empty"),  # was EOFError
        ("a bare .npy", _bare_npy(), "neither a packed record"),  # was TypeError
        ("an unknown array", _packed_with(["colour", "<f8", [0]]), "unknown array 'colour'"),
        ("a pickle", b"\x80\x04K\x01.", "neither a packed record"),
        ("npz holding a string", npz_bytes(record(), theta=np.array(["a"])), "theta is not"),
        ("npz without a field", npz_bytes(record())[:-22], "not readable"),
        ("a huge shape", _packed_with(["start_positions", "<f8", [10**12]]), "more than"),
        ("an object dtype", _packed_with(["start_positions", "|O", [1]]), "has dtype '|O'"),
        ("a float episode", packed({"arrays": [], "scalars": {"episode": 1.5}}, b""), "no array"),
        ("a head that is a list", packed([1, 2], b""), "not an object"),
        ("a header past the end", PACKED_MAGIC + b"\xff\x00\x00\x00{}", "runs past its end"),
    ],
)
def test_malformed_payloads_are_one_line_record_errors(case, data, says):
    """The three of the review (an empty payload raised EOFError, a bare .npy and an unknown
    array TypeError) and their kin: each a ``RecordError`` of one line saying what is wrong."""
    assert says in _one_line_error(data), case


def test_the_scalars_must_have_their_types():
    head, body = _head_and_body(record())
    for name, bad in [("episode", 1.5), ("episode", True), ("kind", 3), ("ball_moved", 1),
                      ("settle_s", "0.5"), ("settle_s", 10**400), ("module", None)]:  # fmt: skip
        wrong = json.loads(json.dumps(head))
        wrong["scalars"][name] = bad
        assert f"{name} is" in _one_line_error(packed(wrong, body)), (name, bad)
    ints = json.loads(json.dumps(head))
    ints["scalars"]["settle_s"] = 1  # a float field takes an integer
    assert EpisodeRecord.from_bytes(packed(ints, body)).settle_s == 1.0


# ---- the property: any bytes end in a record or one line ---------------------------------------


def examples(n: int) -> settings:
    """``n`` examples in the suite; the ``fuzz`` profile's count under ``--hypothesis-profile
    fuzz`` (tests/conftest.py)."""
    fuzzing = settings.get_current_profile_name() == "fuzz"
    common = {"deadline": None, "suppress_health_check": list(HealthCheck)}
    return settings(**common) if fuzzing else settings(max_examples=n, **common)


json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**70), 2**70) | st.floats() | st.text(max_size=6),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner),
    max_leaves=10,
)
names = st.sampled_from(ARRAYS) | st.text(max_size=8)
dtypes = st.sampled_from(["<f8", ">f8", "|u1", "<i8", "|b1", "<f2", "|O", "<U3", "|V4", "f8,i4",
                          "(2,)f8", "<c16", "M8[s]", "foo", ""]) | st.text(max_size=6)  # fmt: skip
shapes = st.lists(st.integers(-2, 6), max_size=4) | json_values
entries = st.tuples(names, dtypes, shapes).map(list) | json_values
scalars = st.fixed_dictionaries({}, optional={n: json_values for n in SCALARS}) | json_values


@st.composite
def headers(draw: st.DrawFn) -> bytes:
    """A packed record with a drawn header (arrays and scalars of any JSON), and a body that
    holds the header's arrays' bytes or not."""
    head = {"arrays": draw(st.lists(entries, max_size=12) | json_values), "scalars": draw(scalars)}
    if draw(st.booleans()):  # start from a good header, change a few things
        head, _ = _head_and_body(record(draw(st.integers(0, 9))))
        for _ in range(draw(st.integers(1, 3))):
            target = draw(st.sampled_from(["arrays", "scalars"]))
            if target == "arrays" and head["arrays"]:
                i = draw(st.integers(0, len(head["arrays"]) - 1))
                head["arrays"][i] = draw(entries)
            else:
                head["scalars"][draw(st.sampled_from(SCALARS))] = draw(json_values)
    size = draw(st.integers(0, 600))
    body = draw(st.sampled_from([zlib.compress(bytes(size)), bytes(size)]) | st.binary(max_size=60))
    return packed(head if draw(st.booleans()) else draw(json_values), body)


@st.composite
def mutated(draw: st.DrawFn) -> bytes:
    """A good record, packed or npz (with extra members or not), then bytes changed: flipped,
    zeroed, cut, or inserted."""
    rec = record(draw(st.integers(0, 9)), ticks=draw(st.integers(0, 3)))
    form = draw(st.sampled_from(["packed", "npz", "npz+"]))
    extra = {draw(names) or "x": np.zeros(draw(st.integers(0, 3)))} if form == "npz+" else {}
    data = bytearray(rec.to_bytes() if form == "packed" else npz_bytes(rec, **extra))
    for _ in range(draw(st.integers(0, 4))):
        at = draw(st.integers(0, len(data)))
        op = draw(st.sampled_from(["flip", "zeros", "cut", "insert"]))
        if op == "flip" and at < len(data):
            data[at] ^= 1 << draw(st.integers(0, 7))
        elif op == "zeros":
            data[at : at + draw(st.integers(1, 64))] = bytes(min(64, len(data) - at))
        elif op == "cut":
            del data[at:]
        else:
            data[at:at] = draw(st.binary(min_size=1, max_size=16))
    return bytes(data)


payloads = st.one_of(
    st.binary(max_size=200),
    st.builds(lambda tail: PACKED_MAGIC + tail, st.binary(max_size=64)),
    st.builds(lambda tail: b"PK\x03\x04" + tail, st.binary(max_size=64)),
    headers(),
    mutated(),
)

DECODER_EXAMPLES = 600


def test_any_bytes_decode_to_a_record_or_a_one_line_record_error():
    """The class behind the review's crash: the decoder is given arbitrary bytes, mutated
    records of both forms and drawn headers; it returns a record or raises ``RecordError``
    (one line), never another exception."""
    seen = {"examples": 0, "records": 0, "errors": 0}

    @examples(DECODER_EXAMPLES)
    @given(payloads)
    def decode(data: bytes) -> None:
        seen["examples"] += 1
        try:
            rec = EpisodeRecord.from_bytes(data)
        except RecordError as exc:
            assert "\n" not in str(exc), str(exc)
            seen["errors"] += 1
            return
        assert isinstance(rec, EpisodeRecord)
        seen["records"] += 1

    decode()
    print(f"record decoder: {seen}")  # the count for the record (pytest -s)
    assert seen["examples"] >= min(DECODER_EXAMPLES, 100) and seen["records"] and seen["errors"]
