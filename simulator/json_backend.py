"""The simulator as ArduPilot SITL's physics: its JSON interface (``--model JSON``), in lockstep.

ArduPilot's SITL firmware sends one binary servo packet per physics step to UDP port 9002 (+10 per
instance) and waits for the answer: one JSON object of the vehicle's state, framed ``"\\n{...}\\n"``,
sent back to the packet's address. The firmware's clock advances by the state's ``timestamp``, so the
two run in lockstep at the physics' pace (ArduPilot ``libraries/SITL/SIM_JSON.cpp``, read to learn the
interface; nothing of it is copied here).

Packet (little endian): uint16 magic (18458: 16 channels, 29569: 32), uint16 frame_rate (Hz),
uint32 frame_count, uint16 pwm[16 or 32] (µs). A packet whose frame_count equals the last one's is
the firmware re-sending after a lost answer: it is answered again without stepping.

The state: ``timestamp`` (s), ``imu.gyro`` (rad/s, body FRD), ``imu.accel_body`` (m/s², body FRD,
specific force: the acceleration less gravity, so -g on z at rest), ``position`` (m, NED from home),
``velocity`` (m/s, NED) and ``attitude`` (roll, pitch, yaw in rad). ArduPilot's reader expects the
value right after the key's colon: the JSON is compact, without spaces.

Skid steering (ArduPilot ``AR_Motors``): the servo functions 73 (left throttle) and 74 (right
throttle), by default on SERVO1 and SERVO3, are "angle" outputs of ±1000: TRIM is zero thrust, MAX
full ahead, MIN full astern, each side scaled apart; SERVOn_REVERSED swaps them. Left is the port
thruster, right the starboard one. A PWM of 0 (no output) is no thrust.

The truth is :class:`simulator.core.SimulatorCore`'s: the same vessel, ESC lag, waves, current and
traffic as the HIL MAVLink server; one answer steps it by one core frame (``1 / sensors.imu.rate_hz``).
"""

from __future__ import annotations

import math
import socket
import struct
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TypedDict

from simulator.core import Command, SimulatorCore, TruthState
from simulator.sensors import G

MAGIC_16 = 18458
MAGIC_32 = 29569
HEADER = struct.Struct("<HHI")
LEFT_THROTTLE, RIGHT_THROTTLE = 73, 74      # ArduPilot SRV_Channel functions
DEFAULT_LEFT_CHANNEL, DEFAULT_RIGHT_CHANNEL = 1, 3
MAX_DATAGRAM = 512


class JsonLinkCounters(TypedDict):
    """The servo packets from the firmware: taken, repeated (answered again without a step), malformed;
    the physics steps, the firmware's physics rate (Hz) and packets from a second sender."""

    packets: int
    repeats: int
    malformed: int
    steps: int
    frame_rate_hz: int
    wrong_peer: int


class JsonPhysicsSummary(TypedDict):
    """:meth:`JsonPhysics.summary`: the packets, the steps, simulated time (s), distance run (m), the truth
    at the end."""

    packets: int
    repeats: int
    malformed: int
    steps: int
    sim_time_s: float
    frame_rate_hz: int
    distance_m: float
    final_state: TruthState


class JsonServerSummary(JsonPhysicsSummary):
    """:meth:`JsonServer.run`: the physics' summary, packets from a second sender, and whether it ended
    because the firmware went quiet."""

    wrong_peer: int
    idle_end: bool


@dataclass(frozen=True)
class ServoPacket:
    """One servo packet: ``frame_rate`` (Hz), ``frame_count`` and the PWM values (µs), 16 or 32."""

    frame_rate: int
    frame_count: int
    pwm: tuple[int, ...]


def parse_servo_packet(data: bytes) -> ServoPacket | None:
    """The packet in ``data``, or None when its size or magic is not one of the interface's."""
    if len(data) < HEADER.size:
        return None
    magic, rate, count = HEADER.unpack_from(data)
    channels = {MAGIC_16: 16, MAGIC_32: 32}.get(magic)
    if channels is None or len(data) != HEADER.size + 2 * channels:
        return None
    return ServoPacket(rate, count, struct.unpack_from(f"<{channels}H", data, HEADER.size))


def encode_servo_packet(frame_rate: int, frame_count: int, pwm: tuple[int, ...]) -> bytes:
    """The packet ArduPilot sends (tests and the bench's recorded exchanges use it)."""
    magic = MAGIC_16 if len(pwm) == 16 else MAGIC_32
    if len(pwm) not in (16, 32):
        raise ValueError("pwm: 16 or 32 values")
    return HEADER.pack(magic, frame_rate, frame_count) + struct.pack(f"<{len(pwm)}H", *pwm)


@dataclass(frozen=True)
class ChannelRange:
    """One servo output's PWM range (µs): ``trim`` is zero, ``max`` +1 and ``min`` -1."""

    min: float = 1100.0
    trim: float = 1500.0
    max: float = 1900.0
    reversed: bool = False

    def __post_init__(self) -> None:
        if not (0 < self.min < self.trim < self.max < 65536):
            raise ValueError(f"servo range: need 0 < MIN < TRIM < MAX, got {self.min:g}/{self.trim:g}/{self.max:g}")

    def normalised(self, pwm: int) -> float:
        """The channel's command in [-1, 1]; 0 for a PWM of 0 (the output is off)."""
        if pwm == 0:
            return 0.0
        if pwm >= self.trim:
            x = min(1.0, (pwm - self.trim) / (self.max - self.trim))
        else:
            x = max(-1.0, (pwm - self.trim) / (self.trim - self.min))
        return -x if self.reversed else x


@dataclass(frozen=True)
class SkidMixer:
    """PWM to (port, starboard) thruster commands in [-1, 1]; channels are 1-based servo numbers."""

    left_channel: int = DEFAULT_LEFT_CHANNEL
    right_channel: int = DEFAULT_RIGHT_CHANNEL
    left: ChannelRange = ChannelRange()
    right: ChannelRange = ChannelRange()

    @classmethod
    def from_params(cls, params: Mapping[str, float]) -> SkidMixer:
        """From ArduPilot parameters (SERVOn_FUNCTION/MIN/TRIM/MAX/REVERSED, ArduPilot's defaults
        where absent). ValueError when no channel or two channels have the left or right function."""
        def channel(function: int, default: int) -> int:
            found = [n for n in range(1, 33) if int(params.get(f"SERVO{n}_FUNCTION", -1)) == function]
            if len(found) > 1:
                raise ValueError(f"SERVOn_FUNCTION: {function} is set on SERVO{found[0]} and SERVO{found[1]}")
            if not found:
                raise ValueError(f"SERVOn_FUNCTION: no channel has function {function} (skid steering)")
            return found[0]

        def rng(n: int) -> ChannelRange:
            return ChannelRange(float(params.get(f"SERVO{n}_MIN", 1100)), float(params.get(f"SERVO{n}_TRIM", 1500)),
                                float(params.get(f"SERVO{n}_MAX", 1900)), bool(params.get(f"SERVO{n}_REVERSED", 0)))

        left, right = channel(LEFT_THROTTLE, DEFAULT_LEFT_CHANNEL), channel(RIGHT_THROTTLE, DEFAULT_RIGHT_CHANNEL)
        return cls(left, right, rng(left), rng(right))

    def controls(self, pwm: tuple[int, ...]) -> tuple[float, float]:
        """(port, starboard) commands; a channel beyond the packet's is off."""
        def at(n: int) -> int:
            return pwm[n - 1] if n <= len(pwm) else 0

        return self.left.normalised(at(self.left_channel)), self.right.normalised(at(self.right_channel))


def _num(x: float) -> str:
    """A finite float as JSON (a non-finite one, which the truth never holds, as 0)."""
    return repr(round(x, 9)) if math.isfinite(x) else "0.0"


def state_json(t: float, state: tuple[float, ...], accel: tuple[float, float], home: tuple[float, float]) -> bytes:
    """The state answer, framed and compact: ``state`` (x north, y east, psi, u, v, r; m, rad, m/s,
    rad/s) at ``t`` (s), ``accel`` (m/s², body x and y, over ground), ``home`` (north, east) in m.
    Numbers are rounded to 1e-9 (non-finite ones, which the truth never holds, sent as 0)."""
    x, y, psi, u, v, r = state
    c, s = math.cos(psi), math.sin(psi)
    vn, ve = u * c - v * s, u * s + v * c
    n = _num
    text = (f'{{"timestamp":{n(t)},"imu":{{"gyro":[0.0,0.0,{n(r)}],"accel_body":[{n(accel[0])},{n(accel[1])},'
            f'{n(-G)}]}},"position":[{n(x - home[0])},{n(y - home[1])},0.0],"attitude":[0.0,0.0,'
            f'{n(math.atan2(s, c))}],"velocity":[{n(vn)},{n(ve)},0.0]}}')
    return b"\n" + text.encode() + b"\n"


class JsonPhysics:
    """A :class:`SimulatorCore` answering servo packets (no sockets: :class:`JsonServer` has them)."""

    def __init__(self, core: SimulatorCore, mixer: SkidMixer, home: tuple[float, float]) -> None:
        """``home``: ArduPilot's home (north, east) in m of the core's frame."""
        self.core, self.mixer, self.home = core, mixer, home
        self.last_count: int | None = None
        self.last_answer = b""
        self.packets = 0
        self.repeats = 0          # packets re-sent by the firmware (answered again, no step)
        self.malformed = 0
        self.frame_rate = 0       # Hz, the firmware's last reported physics rate
        # Moored: the boat stays where it is, at rest, while time passes (an autopilot's boot and set-up,
        # as at a quay); waves and current act again once it is let go.
        self.moored = False

    def answer(self, data: bytes) -> bytes | None:
        """The state answer to one datagram (None: not a servo packet, counted in ``malformed``)."""
        pkt = parse_servo_packet(data)
        if pkt is None:
            self.malformed += 1
            return None
        self.packets += 1
        self.frame_rate = pkt.frame_rate
        if pkt.frame_count == self.last_count and self.last_answer:
            self.repeats += 1
            return self.last_answer
        self.last_count = pkt.frame_count
        core = self.core
        core.apply(Command(core.time_usec, *self.mixer.controls(pkt.pwm)))
        if self.moored:
            core.n += 1     # time passes; the boat, held at its mooring, neither moves nor accelerates
            accel = (0.0, 0.0)
        else:
            core.step()
            accel = self.acceleration()
        self.last_answer = state_json(core.t, core.state, accel, self.home)
        return self.last_answer

    def acceleration(self) -> tuple[float, float]:
        """Acceleration over ground (m/s², body x and y) now."""
        _, _, _, u, v, r = self.core.state
        d = self.core.derivative()
        return d[3] - v * r, d[4] + u * r

    def summary(self) -> JsonPhysicsSummary:
        c = self.core
        return JsonPhysicsSummary(packets=self.packets, repeats=self.repeats, malformed=self.malformed, steps=c.n,
                                  sim_time_s=c.t, frame_rate_hz=self.frame_rate, distance_m=c.distance,
                                  final_state=c.truth())


class JsonServer:
    """:class:`JsonPhysics` on a UDP socket: answers each packet to its sender, until ``duration``
    simulated seconds (0: never), :meth:`stop`, or ``wall_timeout`` wall seconds without a packet.

    ``after_step(core)`` runs after every step, before the answer is sent: the firmware is waiting,
    so what it does happens at a fixed simulated time (the run's judge, ground-station commands)."""

    def __init__(self, physics: JsonPhysics, bind: tuple[str, int], duration: float = 0.0,
                 after_step: Callable[[SimulatorCore], None] | None = None, idle_timeout: float = 30.0) -> None:
        self.physics, self.duration, self.after_step, self.idle_timeout = physics, duration, after_step, idle_timeout
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind(bind)
        except OSError as exc:
            self.sock.close()
            raise ValueError(f"JSON physics port {bind[0]}:{bind[1]}: {exc.strerror or exc}") from None
        self.port = self.sock.getsockname()[1]
        self.end_frame = int(round(duration / physics.core.frame_dt)) if duration > 0 else None
        self._stop = False
        self.idle = False          # ended because no packet came for idle_timeout
        self.peer: tuple[str, int] | None = None
        self.wrong_peer = 0

    def stop(self) -> None:
        self._stop = True

    def done(self) -> bool:
        return self._stop or (self.end_frame is not None and self.physics.core.n >= self.end_frame)

    def run(self) -> JsonServerSummary:
        """Serve until done; the physics' summary."""
        last = time.monotonic()
        self.sock.settimeout(0.1)
        while not self.done():
            try:
                data, sender = self.sock.recvfrom(MAX_DATAGRAM)
            except TimeoutError:
                if time.monotonic() - last > self.idle_timeout:
                    self.idle = True
                    break
                continue
            # The first sender is the firmware; a packet from elsewhere is refused (counted).
            if self.peer is None:
                self.peer = sender
            elif sender != self.peer:
                self.wrong_peer += 1
                continue
            last = time.monotonic()
            n = self.physics.core.n
            reply = self.physics.answer(data)
            if reply is None:
                continue
            if self.after_step is not None and self.physics.core.n != n:
                self.after_step(self.physics.core)
            self.sock.sendto(reply, sender)
        return JsonServerSummary(**self.physics.summary(), wrong_peer=self.wrong_peer, idle_end=self.idle)

    def close(self) -> None:
        self.sock.close()
