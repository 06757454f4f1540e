"""How the Dynamixel bus (``robot/dynamixel/bus.py``) matches the status packets it reads to the
requests they answer (``Replies``, ``match_reply``: per servo, oldest first, by size; a late
reply is recognised and set aside) and learns the reply latency every timeout allows for
(``LatencyEstimate``, as TCP's retransmission timer); the bus's counters (``BusCounters``)."""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Protocol

from robot.dynamixel import protocol as proto

# The slack adapts to the reply latency the bus measures (``LatencyEstimate``), never below
# ``latency_s`` and never above this, s. Guess: a USB adapter at its worst (a 16 ms latency
# timer, a busy host) answers well within it; on 2 cores at load 8 an emulator's reply was
# seen up to about 0.3 s late. A reply later than this counts as lost.
MAX_LATENCY_S = 0.5
# Each retry of a call waits this many times longer than the attempt before (20, 80, 320 ms
# from the default slack), up to MAX_LATENCY_S: a reply that is late rather than lost is
# still caught, and a servo that is gone is reported after at most the sum. Guess; 2 (TCP's,
# RFC 6298 5.5) let the soak's 30 ms late replies (2 ms floor) run out every retry.
RETRY_BACKOFF = 4.0
# Gains of the latency estimate: the smoothed latency and its mean deviation, as TCP's
# retransmission timer (RFC 6298: alpha 1/8, beta 1/4; slack = mean + 4 deviations).
LATENCY_GAIN, DEVIATION_GAIN, DEVIATIONS = 1 / 8, 1 / 4, 4.0


@dataclass
class BusCounters:
    """Totals since the bus was created (or ``reset``)."""

    calls: int = 0
    retries: int = 0  # extra attempts made after a timeout or a corrupt reply
    timeouts: int = 0  # attempts that ended with missing replies and nothing corrupt
    crc_errors: int = 0  # corrupt frames received, and CRC errors reported by servos
    servo_errors: int = 0  # status packets with an error number (ServoError raised)
    alerts: int = 0  # status packets with the alert bit (HardwareAlertError raised)
    # status packets that came after their exchange had given up on them: recognised (each
    # servo answers its requests in order) and set aside, never taken for a later call's
    late_replies: int = 0
    # total duration of the calls that needed a retry, s: an upper bound of what the faults
    # cost (the first attempt's wait for the timeout, then the retries)
    retried_call_s: float = 0.0

    def reset(self) -> None:
        for f in fields(self):
            setattr(self, f.name, 0)

    def as_dict(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass
class LatencyEstimate:
    """The reply latency beyond the wire time (adapter, OS, servo), learnt from the replies:
    the slack every timeout adds (``slack``), between ``floor`` and ``cap`` (the floor wins
    when it is the larger: a slack asked for is kept), s.

    A sample is how much later than its wire time and return delays a reply was read, from
    the request it answers. After a retry that is ambiguous (the first reply may answer the
    first request, late, or the retry, the first reply lost): it gives no sample (Karn's
    rule) until a second reply comes and shows the first was late; a reply that may be a
    later call's (``Replies.set_aside``) gives none until that call's own reply comes too.
    """

    floor: float
    cap: float = MAX_LATENCY_S
    mean: float | None = None
    deviation: float = 0.0
    largest: float = 0.0  # the largest sample seen, s
    samples: int = 0

    def add(self, sample: float) -> None:
        sample = max(0.0, sample)
        self.largest = max(self.largest, sample)
        self.samples += 1
        if self.mean is None:
            self.mean, self.deviation = sample, sample / 2
            return
        self.deviation += DEVIATION_GAIN * (abs(sample - self.mean) - self.deviation)
        self.mean += LATENCY_GAIN * (sample - self.mean)

    @property
    def slack(self) -> float:
        """The slack of a first attempt, s."""
        if self.mean is None:
            return self.floor
        return max(self.floor, min(self.cap, self.mean + DEVIATIONS * self.deviation))

    @property
    def longest(self) -> float:
        """The most slack any attempt gets, s: a reply later than that counts as lost."""
        return max(self.cap, self.floor)

    def slack_of_attempt(self, attempt: int) -> float:
        """The slack of attempt ``attempt`` (0: the first) of a call, s."""
        return min(self.longest, self.slack * RETRY_BACKOFF**attempt)


@dataclass
class Expected:
    """A status packet asked for and not yet received: by which call, when, of what size.
    ``spare``: its call already has this servo's answer (a retry's, or the first attempt's
    come late): a reply counted against it is surplus and gives no latency sample."""

    call: int
    n_params: int
    sent_at: float
    nominal_s: float  # wire time and return delays up to this reply, s
    expires: float
    spare: bool = False
    deadline: float = 0.0  # when its attempt stopped waiting for it, s (monotonic)
    question: bytes = b""  # what it asked (instruction, and address + length for reads)


FORGOTTEN = Expected(-1, -1, 0.0, 0.0, 0.0)  # what _match returns for a reply of nobody's


def match_reply(queue: deque[Expected] | None, status: proto.StatusPacket) -> Expected | None:
    """The request ``status`` answers, taken off its servo's ``queue``: the oldest one, as a
    servo answers in order, unless the size differs (a READ's reply holds exactly the bytes
    asked for; a status with an error number holds none and answers the oldest): then the
    first whose size fits, the ones before it lost; ``FORGOTTEN`` when none fits (the reply
    of a request given up on and forgotten); None when nothing is awaited from that servo."""
    if not queue:
        return None
    if status.error_code:
        return queue.popleft()
    n = len(status.params)
    for k, entry in enumerate(queue):
        if entry.n_params == n:
            for _ in range(k):
                queue.popleft()  # asked before, of another size: their replies were lost
            return queue.popleft()
    return FORGOTTEN


def question_of(packet: proto.InstructionPacket) -> bytes:
    """What ``packet`` asks each servo, as the servo sees it: a READ and a SYNC READ of the
    same address and length ask the same; anything else, its instruction and parameters."""
    if packet.instruction in (proto.Instruction.READ, proto.Instruction.SYNC_READ):
        return b"R" + bytes(packet.params[:4])
    return bytes([packet.instruction]) + bytes(packet.params)


class ReplyBook(Protocol):
    """What ``Replies`` reads and keeps of its bus (``DynamixelBus`` is one): the requests still
    unanswered per servo, the stream decoder, the counters, the latency estimate."""

    _expected: dict[int, deque[Expected]]
    _decoder: proto.Decoder
    counters: BusCounters
    latency: LatencyEstimate


class Replies:
    """What one exchange of call ``call`` received, matched against the requests still
    unanswered (``DynamixelBus._expected``, see ``DynamixelBus._exchange``)."""

    def __init__(self, bus: ReplyBook, call: int, expect: Mapping[int, int]) -> None:
        self.bus = bus
        self.call = call
        self.expect = expect
        self.got: dict[int, proto.StatusPacket] = {}
        self.corrupt = 0
        # late for an older call, it seemed: id -> (status, its latency sample as such)
        self.set_aside: dict[int, tuple[proto.StatusPacket, float | None, bytes]] = {}
        self.latency: float | None = None  # the latest of this call's replies, beyond nominal, s

    @property
    def complete(self) -> bool:
        return all(i in self.got for i in self.expect)

    def _wanted(self, status: proto.StatusPacket) -> bool:
        n = self.expect.get(status.id)
        return n is not None and status.id not in self.got and len(status.params) == n

    def _answered(self, entry: Expected, sid: int, now: float) -> float | None:
        """``entry`` got its reply at ``now``: the other requests of its call to that servo
        become spare. Returns the latency sample, or None when the reply may answer another
        request of its call than ``entry`` (Karn's rule: a retry's, the first reply lost).
        A spare entry's reply is a second answer to one call: the first was late, not lost,
        and this one, the retry's, is as late as it says."""
        others = [o for o in self.bus._expected.get(sid, ()) if o.call == entry.call]
        for other in others:
            other.spare = True  # surplus now: awaited only up to its attempt's deadline
        if others and not entry.spare:
            return None
        return now - entry.sent_at - entry.nominal_s

    def take(self, chunk: bytes) -> None:
        """Decode ``chunk`` and sort what it holds: this call's replies, late ones of older
        calls, corrupt frames."""
        if not chunk:
            return
        bus = self.bus
        now = time.monotonic()
        for item in bus._decoder.feed(chunk):
            if isinstance(item, proto.InstructionPacket):
                continue  # our own echo
            queue = bus._expected.get(item.id)
            while queue and queue[0].expires < now:
                queue.popleft()  # older than any reply can be: it was lost
            if isinstance(item, proto.CorruptFrame):
                entry = queue.popleft() if queue else None
                bus.counters.crc_errors += 1
                if entry is None or entry.call == self.call:
                    self.corrupt += 1  # ours, or nobody's (its id may be damaged)
                continue
            entry = match_reply(queue, item)
            if entry is FORGOTTEN:
                bus.counters.late_replies += 1  # for a request no longer remembered
                continue
            sample = None if entry is None else self._answered(entry, item.id, now)
            if entry is not None and entry.call == self.call and entry.spare:
                bus.counters.late_replies += 1  # an earlier attempt's, after a retry's
                if sample is not None:
                    bus.latency.add(sample)
                continue
            if entry is None or entry.call == self.call:
                if item.id in self.expect and (entry is not None or self._wanted(item)):
                    self.got.setdefault(item.id, item)  # unasked for but awaited: ours
                    if sample is not None:
                        self.latency = max(sample, self.latency or 0.0)
                continue
            if self._wanted(item):
                # this call's if the request it was counted against lost its reply, unless
                # this call's own comes too: its latency is known only then
                self.set_aside[item.id] = (item, sample, entry.question)
                continue
            bus.counters.late_replies += 1
            if sample is not None:  # an older call's first answer from this servo, late
                bus.latency.add(sample)
        for sid in [i for i in self.set_aside if i in self.got]:
            _, sample, _ = self.set_aside.pop(sid)  # the servo's own answer came: that one was late
            bus.counters.late_replies += 1
            if sample is not None:
                bus.latency.add(sample)

    def take_set_aside(self, question: bytes) -> None:
        """The attempt ends without some servos' replies: a reply of theirs set aside as
        late was this call's after all (the request it was counted against had lost its
        reply); take it, and forget this call's request it answered. Only a reply counted
        against a request of the same ``question``: one that asked something else may be
        that request's late answer, a wrong value for this call (the retry asks again)."""
        for sid, (status, _, asked) in self.set_aside.items():
            if sid in self.got:
                continue
            if asked != question:
                self.bus.counters.late_replies += 1
                continue
            self.got[sid] = status
            queue = self.bus._expected.get(sid, deque())
            for k, entry in enumerate(queue):
                if entry.call == self.call:
                    del queue[k]
                    break
        self.set_aside.clear()
