"""One reusable `can.Message` and value vector per transmitted DBC message (hot path:
encode in place, send the same object every time)."""

from __future__ import annotations

import can

from protocol.codec import CODECS, EncodeStatus


class Outbox:
    def __init__(self, name: str):
        self.codec = CODECS[name]
        self.values = self.codec.new_values()
        self.message = can.Message(arbitration_id=self.codec.frame_id, data=self.codec.new_buffer(),
                                   is_extended_id=False)
        self.index = self.codec.index

    def encode(self) -> bool:
        """Encode `values` into the message; False when a value was not finite (nothing to send)."""
        return self.codec.encode_into(self.values, self.message.data) is not EncodeStatus.REJECTED
