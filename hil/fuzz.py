"""`hydrapod hil fuzz`: random frames into the receive side of the controller and into a
decoder of every DBC message; no exception may escape, and every frame must be counted.

Frames come from a seeded NumPy generator, so a run is reproducible from its seed:
- a quarter are well-formed for a random DBC message (right length, valid CRC, random
  payload; half of them with the message's next alive counter, half a random one), so
  many pass E2E and reach the decoders' scaling and the controller's host-command parser
  (HOST_CMD, HOST_WAYPOINT_*) with arbitrary values: commands out of range, absurd
  waypoints, reused tags;
- the rest are random ids (standard and extended), random lengths 0-8, random bytes, and
  now and then remote, error or FD frames.
Targets:
- `decoder`: a `FrameDecoder` of the whole DBC; counted = sum of its status counts plus
  its unknown frames;
- `controller`: the hexapod controller's own `ControllerLoop.dispatch`, the controller
  updated every 256 frames against the emulated hexapod in process (so the host frames
  queued meanwhile are carried out and accepted commands move it through its states);
  counted as above on the loop's decoder, and the valve setpoints must stay finite.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import can
import numpy as np

from firmware_py.config import load_config
from firmware_py.runtime.loop import ControllerLoop
from hil.in_process import InProcessLoop
from plant_emulator.params import load_config as load_emulator_config
from protocol import e2e
from protocol.codec import CODECS, FrameDecoder, RxStatus

VALID_SHARE = 0.25
CYCLE_EVERY = 256         # controller target: frames per update (~3,900 updates in 10^6 frames)
TARGETS = ("decoder", "controller")


@dataclass
class FuzzReport:
    target: str
    frames: int
    seed: int
    exceptions: int
    counted: int              # frames the receiver classified (every one must be)
    accepted: int             # of them OK (E2E passed)
    rejected: int             # CRC, sequence, length, repeated
    unknown: int              # ids not ours, extended, remote, error, FD
    host_commands: int        # controller: HOST_CMD frames that reached the parser
    non_finite_outputs: int   # controller: cycles with a non-finite valve setpoint
    seconds: float
    first_exception: str = ""

    @property
    def ok(self) -> bool:
        return self.exceptions == 0 and self.counted == self.frames and self.non_finite_outputs == 0


class _QuietBus:
    """The controller's sends go nowhere; nothing arrives but what the fuzzer dispatches."""

    def __init__(self):
        self.sent = 0

    def send(self, msg, timeout=None) -> None:
        self.sent += 1

    def recv(self, timeout=None):
        return None


def frames(count: int, seed: int, names: list[str]):
    """Yield `count` random `can.Message`s (one object, rewritten each time)."""
    rng = np.random.default_rng(seed)
    codecs = [CODECS[n] for n in names]
    msg = can.Message(arbitration_id=0, data=bytearray(8), is_extended_id=False)
    next_counter = [0] * len(codecs)
    block = 4096
    done = 0
    while done < count:
        n = min(block, count - done)
        kind = rng.random(n)
        pick = rng.integers(0, len(codecs), n)
        ids = rng.integers(0, 0x800, n)
        ext_ids = rng.integers(0, 0x20000000, n)
        lengths = rng.integers(0, 9, n)
        payload = rng.integers(0, 256, (n, 8), dtype=np.uint8)
        counters = rng.integers(0, 16, n)
        odd = rng.random(n)
        for i in range(n):
            msg.is_extended_id = msg.is_remote_frame = msg.is_error_frame = msg.is_fd = False
            if kind[i] < VALID_SHARE:
                codec = codecs[pick[i]]
                data = bytearray(payload[i, :codec.dlc].tobytes())
                if codec.e2e:
                    counter = int(counters[i])
                    if counter % 2:                      # in sequence
                        counter = next_counter[pick[i]]
                        next_counter[pick[i]] = (counter + 1) % e2e.COUNTER_MODULO
                    data[1] = (data[1] & 0xF0) | counter
                    e2e.protect(data, codec.data_id, codec.dlc)
                msg.arbitration_id = codec.frame_id
            else:
                data = bytearray(payload[i, :lengths[i]].tobytes())
                msg.arbitration_id = int(ids[i])
                if odd[i] < 0.02:
                    msg.is_extended_id, msg.arbitration_id = True, int(ext_ids[i])
                elif odd[i] < 0.03:
                    msg.is_remote_frame = True
                elif odd[i] < 0.04:
                    msg.is_error_frame = True
                elif odd[i] < 0.05:
                    msg.is_fd = True
            msg.data = data
            msg.dlc = len(data)
            yield msg
        done += n


def fuzz_decoder(count: int, seed: int) -> FuzzReport:
    decoder = FrameDecoder()
    exceptions, first = 0, ""
    start = time.perf_counter()
    for msg in frames(count, seed, list(CODECS)):
        try:
            decoder.receive_message(msg)
        except Exception as error:
            exceptions += 1
            first = first or f"{type(error).__name__}: {error}"
    return _report("decoder", count, seed, (decoder,), exceptions, first, 0, 0, time.perf_counter() - start)


def fuzz_controller(count: int, seed: int, controller: str = "model-based") -> FuzzReport:
    ctl_cfg, emulator_cfg = load_config(), load_emulator_config()
    rig = InProcessLoop(ctl_cfg, emulator_cfg, controller)        # the emulated hexapod, in process
    ctl = rig.ctl
    loop = ControllerLoop(_QuietBus(), ctl, 500.0, "lockstep", log=lambda _: None)
    rig.cycle()
    ctl.activated(True)
    decoders = (loop.hardware.decoder, loop.decoder)         # the devices' frames and the host's
    names = [name for decoder in decoders for name in decoder.names]
    exceptions, first, non_finite = 0, "", 0
    start = time.perf_counter()
    for i, msg in enumerate(frames(count, seed, names)):
        try:
            loop.dispatch(msg)                   # host frames reach the controller's HostLink
            if i % CYCLE_EVERY == CYCLE_EVERY - 1:
                rig.cycle()
                if not np.isfinite(rig.cmd.spool).all():
                    non_finite += 1
        except Exception as error:
            exceptions += 1
            first = first or f"{type(error).__name__}: {error}"
    return _report("controller", count, seed, decoders, exceptions, first, loop.stats.host_commands,
                   non_finite, time.perf_counter() - start)


def _report(target, count, seed, decoders, exceptions, first, host_commands, non_finite, seconds) -> FuzzReport:
    """`decoders` in the order a frame meets them: one the last does not know is not ours."""
    counts = sum(decoder.counts.sum(axis=0) for decoder in decoders)
    unknown = decoders[-1].unknown_frames
    counted = int(counts.sum()) - int(counts[RxStatus.NO_NEW_DATA]) + unknown
    accepted = int(counts[RxStatus.OK])
    return FuzzReport(target, count, seed, exceptions, counted, accepted,
                      counted - accepted - unknown, unknown, host_commands,
                      non_finite, round(seconds, 2), first)


def run(targets: list[str], count: int, seed: int) -> list[FuzzReport]:
    runners = {"decoder": fuzz_decoder, "controller": fuzz_controller}
    return [runners[t](count, seed) for t in targets]


def format_reports(reports: list[FuzzReport]) -> str:
    lines = []
    for r in reports:
        lines.append(f"{r.target:<10} {r.frames} frames (seed {r.seed}) in {r.seconds} s: "
                     f"{r.exceptions} exceptions, {r.counted} counted ({r.accepted} OK, {r.rejected} rejected, "
                     f"{r.unknown} not ours), {r.host_commands} host commands parsed, "
                     f"{r.non_finite_outputs} non-finite outputs: {'ok' if r.ok else 'FAILED'}"
                     + (f"; first exception {r.first_exception}" if r.first_exception else ""))
    return "\n".join(lines)


def as_dicts(reports: list[FuzzReport]) -> list[dict]:
    return [{**asdict(r), "ok": r.ok} for r in reports]
