"""Emulator faults named on a command line or in a campaign spec: FAULT:TARGET:PARAM, checked
against the DBC's EMU_CTRL (its FAULT value table and its signals' ranges)."""

from __future__ import annotations

from program.errors import UserInputError


def parse_faults(text: str | None, option: str = "--inject") -> tuple[tuple[str, int, int], ...]:
    """Comma-separated FAULT:TARGET:PARAM, each an EMU_CTRL fault name (the DBC's table), a
    target node and a parameter within what EMU_CTRL carries."""
    if not text:
        return ()
    from protocol.codec import CODECS
    from protocol.enums import EmuFault
    codec = CODECS["EMU_CTRL"]
    ranges = {name: codec.signals[codec.index[name]] for name in ("TARGET", "FAULT_PARAM")}
    known = [f.name for f in EmuFault if f is not EmuFault.NONE]
    faults = []
    for item in text.split(","):
        parts = item.strip().split(":")
        if len(parts) != 3 or parts[0] not in known:
            raise UserInputError(f"{option}: {item.strip()!r} is not FAULT:TARGET:PARAM with FAULT one of "
                                 f"{', '.join(known)}")
        numbers = []
        for text_value, (name, signal) in zip(parts[1:], ranges.items()):
            try:
                value = int(text_value)
            except ValueError:
                value = -1
            if not signal.minimum <= value <= signal.maximum:
                raise UserInputError(f"{option}: {item.strip()!r}: {name} {text_value!r} is not an integer in "
                                     f"{signal.minimum:g}..{signal.maximum:g}")
            numbers.append(value)
        faults.append((parts[0], numbers[0], numbers[1]))
    return tuple(faults)
