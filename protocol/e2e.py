"""AUTOSAR E2E profile 1 protection, in place on a frame's bytearray.

Layout (profile 1, variant with CRC offset 0 and counter offset 8): byte 0 is the CRC-8
(SAE J1850) over the 16-bit data id (both bytes, `E2E_P01_DATAID_BOTH`) and bytes 1..n-1;
the low nibble of byte 1 is the alive counter 0..14 (15 is never sent). The CRC and the
counter arithmetic come from `autosar-e2e`; the receiver's sequence classification below
is ours because the library checks only the CRC.
"""

from __future__ import annotations

from enum import IntEnum

from e2e.p01 import E2E_P01_DATAID_BOTH, e2e_p01_check, e2e_p01_protect

COUNTER_MODULO = 15          # profile 1 counter runs 0..14
DEFAULT_MAX_DELTA_COUNTER = 2  # accept one lost frame between two received ones


class RxStatus(IntEnum):
    """Outcome of receiving (or not receiving) one frame."""

    OK = 0               # fresh, CRC good, counter advanced by 1..max_delta
    REPEATED = 1         # same counter as the last accepted frame: a duplicate
    WRONG_SEQUENCE = 2   # counter jumped by more than max_delta (or went backwards)
    CRC_ERROR = 3        # CRC does not match: corrupted or masqueraded
    NO_NEW_DATA = 4      # expected this cycle, nothing arrived
    BAD_LENGTH = 5       # DLC differs from the DBC
    UNKNOWN_ID = 6       # id not in the DBC (or not decoded by this receiver)


#: Outcomes that mean a frame arrived and was rejected by the E2E check (counted as E2E errors).
E2E_REJECTED = frozenset({RxStatus.REPEATED, RxStatus.WRONG_SEQUENCE, RxStatus.CRC_ERROR, RxStatus.BAD_LENGTH})


def protect(buf: bytearray, data_id: int, length: int) -> None:
    """Advance the alive counter in byte 1 and write the CRC into byte 0, in place."""
    e2e_p01_protect(buf, data_id, data_id_mode=E2E_P01_DATAID_BOTH, length=length, increment_counter=True)


def crc_ok(data: bytearray, data_id: int, length: int) -> bool:
    """CRC check of a frame; `data` must be writable (an autosar-e2e requirement)."""
    return e2e_p01_check(data, data_id, data_id_mode=E2E_P01_DATAID_BOTH, length=length)


def classify_counter(counter: int, last_counter: int, max_delta: int) -> RxStatus:
    """Sequence check of a frame whose CRC is good (profile 1 semantics).

    `last_counter` < 0 means nothing was accepted yet: the first frame is OK.
    """
    if counter >= COUNTER_MODULO:
        return RxStatus.WRONG_SEQUENCE
    if last_counter < 0:
        return RxStatus.OK
    delta = (counter - last_counter) % COUNTER_MODULO
    if delta == 0:
        return RxStatus.REPEATED
    if delta <= max_delta:
        return RxStatus.OK
    return RxStatus.WRONG_SEQUENCE
