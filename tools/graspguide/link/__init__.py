"""The GraspGuide serial link protocol, host side.

* :mod:`.messages` -- GENERATED from ``tools/codegen/link_messages.toml``: ids, enums and
  one dataclass per message (data only);
* :mod:`.message_base` -- what those dataclasses share: field checks, ``pack()``/``unpack()``;
* :mod:`.codec` -- CRC-16/CCITT-FALSE, COBS, ``encode_frame``/``decode_frame``,
  ``encode_message``/``decode_message`` and the incremental :class:`FrameParser`;
* :mod:`.errors` -- the typed :class:`ProtocolError` hierarchy.

The C++ side is ``lib/graspguide_link``; both follow ``docs/protocol.md``.
"""

from graspguide.link import codec, errors, messages
from graspguide.link.codec import (
    Accept,
    DecodedMessage,
    Frame,
    FrameParser,
    ParseEvent,
    SequenceCounter,
    cobs_decode,
    cobs_encode,
    crc16,
    decode_frame,
    decode_message,
    encode_frame,
    encode_message,
)
from graspguide.link.errors import *  # noqa: F401,F403
from graspguide.link.messages import *  # noqa: F401,F403

__all__ = (
    [
        "codec",
        "errors",
        "messages",
        "Accept",
        "DecodedMessage",
        "Frame",
        "FrameParser",
        "ParseEvent",
        "SequenceCounter",
        "cobs_decode",
        "cobs_encode",
        "crc16",
        "decode_frame",
        "decode_message",
        "encode_frame",
        "encode_message",
    ]
    + list(errors.__all__)
    + list(messages.__all__)
)
