"""Peer process for the two-process bus test (run as a script, not collected).

Plays six leg nodes: on every SYNC k it answers LEG_STATE_1..6 carrying k, then expects
VALVE_CMD_1..6 carrying k, in order, before the next SYNC. Prints a JSON summary.
"""

import json
import sys
import time

import can

from protocol.bus import open_bus
from protocol.codec import CODECS, FrameDecoder
from protocol.e2e import RxStatus

READY_ID = 0x7E0     # not in the DBC: test handshake only
FIN_ID = 0x7E1


def position_of(k: int) -> float:      # SI metres on the 0.005 mm grid, distinct per cycle
    return (k % 60000) * 5e-6


def sync_counter_of(k: int) -> int:  # CiA 301 counter 1..240
    return k % 240 + 1


def spool_of(k: int, leg: int) -> float:
    return (((k * 7 + leg) % 32001) - 16000) / 16384


def main(spec: str, cycles: int) -> int:
    bus = open_bus(spec)
    legs = range(1, 7)
    codecs = {n: CODECS[f"LEG_STATE_{n}"] for n in legs}
    state = {n: (c, can.Message(arbitration_id=c.frame_id, data=c.new_buffer(), is_extended_id=False))
             for n, c in codecs.items()}
    values = {n: CODECS[f"LEG_STATE_{n}"].new_values() for n in legs}
    decoder = FrameDecoder([f"VALVE_CMD_{n}" for n in legs] + ["SYNC"])
    ready = can.Message(arbitration_id=READY_ID, data=b"", is_extended_id=False)
    errors, received, k, expect_cmd = [], 0, -1, 7
    last_ready = 0.0
    while True:
        if k < 0 and time.monotonic() - last_ready > 0.02:
            bus.send(ready)
            last_ready = time.monotonic()
        msg = bus.recv(0.02 if k < 0 else 5.0)
        if msg is None:
            if k >= 0:
                errors.append(f"timeout after cycle {k}")
                break
            continue
        received += 1
        if msg.arbitration_id == FIN_ID:
            received -= 1
            break
        status = decoder.receive_message(msg)
        if msg.arbitration_id == CODECS["SYNC"].frame_id:
            counter = int(decoder.values["SYNC"][0])
            if expect_cmd != 7 or counter != sync_counter_of(k + 1):
                errors.append(f"SYNC counter {counter} after cycle {k}, {expect_cmd - 1} commands seen")
            k += 1
            expect_cmd = 1
            for n in legs:
                codec, out = state[n]
                values[n][codec.index["POSITION"]] = position_of(k)
                codec.encode_into(values[n], out.data)
                bus.send(out)
        elif expect_cmd <= 6 and msg.arbitration_id == CODECS[f"VALVE_CMD_{expect_cmd}"].frame_id:
            spool = decoder.values[f"VALVE_CMD_{expect_cmd}"][CODECS["VALVE_CMD_1"].index["SPOOL_SETPOINT"]]
            if status is not RxStatus.OK or abs(spool - spool_of(k, expect_cmd)) > 1e-9:
                errors.append(f"cycle {k} VALVE_CMD_{expect_cmd}: {status.name} spool {spool}")
            expect_cmd += 1
        else:
            errors.append(f"cycle {k}: unexpected id {msg.arbitration_id:#x} (expected command {expect_cmd})")
        if len(errors) > 20:
            break
    lost = int(decoder.lost.sum())
    print(json.dumps({"received": received, "cycles": k + 1, "errors": errors, "lost": lost,
                      "counts": decoder.counts.sum(axis=0).tolist()}))
    bus.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], int(sys.argv[2])))
