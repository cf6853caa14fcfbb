"""Kernel acceptance filter for python-can's udp_multicast frames: what a CAN controller's
hardware filter does, as a classic BPF program on the UDP socket, so a node is not woken
for frames it does not read.

The program reads the arbitration id and the extended flag where `pack_message` puts them
(a msgpack map whose keys come in a fixed order) and applies python-can's filter rule
(`(can_id ^ id) & can_mask == 0`, and `extended` when given). A datagram not laid out like
that is passed on for the bus to count as garbage: the filter only drops frames it has read.
"""

from __future__ import annotations

import ctypes
import itertools
import socket
import struct

SO_ATTACH_FILTER = getattr(socket, "SO_ATTACH_FILTER", 26)
SO_DETACH_FILTER = getattr(socket, "SO_DETACH_FILTER", 27)

# classic BPF opcodes (linux/filter.h)
_LDB_ABS, _LDH_ABS, _LDW_ABS, _LD_LEN = 0x30, 0x28, 0x20, 0x80
_LD_MEM, _ST_MEM, _AND_K = 0x60, 0x02, 0x54
_JA, _JEQ_K, _JGE_K, _RET_K = 0x05, 0x15, 0x35, 0x06
_ACCEPT, _DROP = 0xFFFFFFFF, 0

UDP_HEADER = 8                      # a UDP socket's filter sees the datagram from its UDP header
# pack_message's layout: map of 11 (0x8b); "timestamp" (fixstr 9) and its float64 (0xcb);
# "arbitration_id" (fixstr 14, 0xae) and the id (fixint, or 0xcc/0xcd/0xce and 1/2/4 bytes);
# "is_extended_id" (fixstr 14) and false/true (0xc2/0xc3)
_MAP11, _FLOAT64, _FIXSTR14 = 0x8B, 0xCB, 0xAE
_AT_MAP, _AT_FLOAT, _AT_ID_KEY, _AT_ID = 0, 11, 20, 35
_KEY_LEN = 15
_MIN_FRAME = 56                     # the bytes up to the extended flag of a 4-byte id
_FALSE, _TRUE = 0xC2, 0xC3
_ID_FORMS = ((0xCC, _LDB_ABS, 1), (0xCD, _LDH_ABS, 2), (0xCE, _LDW_ABS, 4))     # uint8/16/32
_M_ID, _M_EXTENDED = 0, 1           # scratch memory: the id, the extended flag's byte


def _ins(code: int, k: int = 0, jt: int = 0, jf: int = 0) -> tuple[int, int, int, int]:
    return code, jt, jf, k


def _accept_unless(byte_at: int, value: int) -> list[tuple]:
    """Pass the datagram on (not a python-can frame) unless the byte at `byte_at` is `value`."""
    return [_ins(_LDB_ABS, UDP_HEADER + byte_at), _ins(_JEQ_K, value, jt=1), _ins(_RET_K, _ACCEPT)]


def _read_id(load: int, at: int, length: int) -> list[tuple]:
    """Store the id (`length` bytes at `at`) and the extended flag after its key."""
    flag_at = at + length + _KEY_LEN
    return ([_ins(load, UDP_HEADER + at), _ins(_ST_MEM, _M_ID)]
            + _accept_unless(at + length, _FIXSTR14)
            + [_ins(_LDB_ABS, UDP_HEADER + flag_at), _ins(_ST_MEM, _M_EXTENDED)])


def acceptance_program(filters: list[dict]) -> list[tuple[int, int, int, int]]:
    """The BPF instructions (code, jt, jf, k) accepting the frames that match any of
    python-can's `filters` (dicts of can_id, can_mask and optional extended)."""
    program = [_ins(_LD_LEN), _ins(_JGE_K, UDP_HEADER + _MIN_FRAME, jt=1), _ins(_RET_K, _ACCEPT)]
    program += _accept_unless(_AT_MAP, _MAP11) + _accept_unless(_AT_FLOAT, _FLOAT64)
    program += _accept_unless(_AT_ID_KEY, _FIXSTR14)
    # the id's form picks a branch that reads it; each branch then jumps to the filters
    branches = [_read_id(_LDB_ABS, _AT_ID, 1)]
    branches += [_read_id(load, _AT_ID + 1, length) for _, load, length in _ID_FORMS]
    tests_at = len(program)
    starts = list(itertools.accumulate((len(b) + 1 for b in branches), initial=tests_at + 3 + len(_ID_FORMS)))
    program.append(_ins(_LDB_ABS, UDP_HEADER + _AT_ID))
    program.append(_ins(_JGE_K, 0x80, jf=starts[0] - (tests_at + 1) - 1))    # < 0x80: a fixint
    for j, (marker, _, _) in enumerate(_ID_FORMS):
        program.append(_ins(_JEQ_K, marker, jt=starts[1 + j] - (tests_at + 2 + j) - 1))
    program.append(_ins(_RET_K, _ACCEPT))                 # a float, negative or 8-byte id: not ours
    for branch, start in zip(branches, starts):
        program += branch + [_ins(_JA, starts[-1] - (start + len(branch)) - 1)]
    for f in filters:
        mask = int(f.get("can_mask", 0x1FFFFFFF)) & 0xFFFFFFFF
        can_id = int(f["can_id"]) & mask
        if "extended" in f:
            flag = _TRUE if f["extended"] else _FALSE
            program += [_ins(_LD_MEM, _M_EXTENDED), _ins(_JEQ_K, flag, jf=4)]
        program += [_ins(_LD_MEM, _M_ID), _ins(_AND_K, mask), _ins(_JEQ_K, can_id, jf=1), _ins(_RET_K, _ACCEPT)]
    program.append(_ins(_RET_K, _DROP))
    return program


def attach(sock: socket.socket, filters: list[dict] | None) -> None:
    """Attach the acceptance program for `filters` to `sock`; None or [] (python-can: every
    frame) detaches any program."""
    if not filters:
        try:
            sock.setsockopt(socket.SOL_SOCKET, SO_DETACH_FILTER, 0)
        except OSError:
            pass   # none attached
        return
    program = acceptance_program(filters)
    raw = b"".join(struct.pack("=HBBI", *ins) for ins in program)
    buffer = ctypes.create_string_buffer(raw, len(raw))
    fprog = struct.pack("@HP", len(program), ctypes.addressof(buffer))
    sock.setsockopt(socket.SOL_SOCKET, SO_ATTACH_FILTER, fprog)
