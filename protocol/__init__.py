"""The contract between swarmloc processes: message types and their validating msgpack codec
(:mod:`.messages`; each robot family's Sense and Act are defined in :mod:`.family_messages`), the
key expressions of a run (:mod:`.keys`), Zenoh session configuration from the conventional
transport flags (:mod:`.session`), and the e-puck body both sides integrate (:mod:`.epuck`).

The message codec and the keys do not import zenoh; only :mod:`.session` does, and it is not
imported here, so ``import swarmloc.protocol`` stays light for pure code.
"""

from swarmloc.protocol.keys import Keys, validate_run_name
from swarmloc.protocol.messages import (
    MAX_MESSAGE_BYTES,
    MAX_RAB_PAYLOAD_BYTES,
    MESSAGE_TYPES,
    PROTOCOL_VERSION,
    EpuckAct,
    EpuckSense,
    ErrorReport,
    Field,
    Join,
    ProtocolError,
    RabMessage,
    RunEnd,
    Welcome,
    WorldState,
    decode,
    encode,
    register_message,
)

__all__ = [
    "MAX_MESSAGE_BYTES",
    "MAX_RAB_PAYLOAD_BYTES",
    "MESSAGE_TYPES",
    "PROTOCOL_VERSION",
    "EpuckAct",
    "EpuckSense",
    "ErrorReport",
    "Field",
    "Join",
    "Keys",
    "ProtocolError",
    "RabMessage",
    "RunEnd",
    "Welcome",
    "WorldState",
    "decode",
    "encode",
    "register_message",
    "validate_run_name",
]
