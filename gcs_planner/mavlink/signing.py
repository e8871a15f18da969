"""MAVLink 2 message signing, shared by the GCS link and the mock vehicles.

A signed link appends to every frame a 13-byte block: link id, a 48-bit timestamp (10 us units since
2015-01-01) and the first 6 bytes of SHA-256(key + frame). Autopilots with signing enabled
(ArduPilot, PX4) ignore unsigned commands, so a field GCS must sign. pymavlink's codec does the
cryptography; this module only derives the key and sets the codec up.

SETUP_SIGNING gives a vehicle its key (``setup_signing_message``); the protocol has no answer, so
the caller checks that the vehicle's frames come back signed with it. An all-zero key with timestamp
0 turns signing off, as ArduPilot reads it.

Choices: the 32-byte key is SHA-256 of a passphrase, as MAVProxy's ``signing setup`` and
QGroundControl derive it, so the same passphrase works across the three. A receiver with a key
rejects unsigned and wrongly signed frames (no ``allow_unsigned_callback``): accepting them would
let anyone on the radio channel spoof the vehicle or the GCS.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Iterable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = [
    "KEY_BYTES",
    "NO_KEY",
    "enable_signing",
    "key_from_passphrase",
    "set_link_key",
    "setup_signing_message",
    "signing_timestamp",
]

KEY_BYTES = 32
NO_KEY = bytes(KEY_BYTES)  # with timestamp 0 in SETUP_SIGNING: turn signing off (ArduPilot's convention)
_EPOCH_2015_S = 1_420_070_400  # 2015-01-01T00:00:00Z, the signing timestamp's origin


def key_from_passphrase(passphrase: str) -> bytes:
    """The 32-byte signing key of a passphrase (SHA-256, as MAVProxy and QGroundControl)."""
    if not passphrase:
        raise ValueError("signing passphrase must not be empty")
    return hashlib.sha256(passphrase.encode()).digest()


def signing_timestamp(now_s: float | None = None) -> int:
    """Signing timestamp for Unix time ``now_s`` [10 us units since 2015-01-01]."""
    return int(((time.time() if now_s is None else now_s) - _EPOCH_2015_S) * 100_000)


def enable_signing(codec: mavlink.MAVLink, key: bytes, *, sign_outgoing: bool, link_id: int = 0) -> None:
    """Give a pymavlink codec the key: it then signs what it packs (``sign_outgoing``) and rejects
    unsigned or badly signed frames it decodes."""
    if len(key) != KEY_BYTES:
        raise ValueError(f"signing key must be {KEY_BYTES} bytes, got {len(key)}")
    codec.signing.secret_key = key
    codec.signing.timestamp = signing_timestamp()
    codec.signing.sign_outgoing = sign_outgoing
    codec.signing.link_id = link_id


def set_link_key(sender: mavlink.MAVLink, receivers: Iterable[mavlink.MAVLink], key: bytes | None) -> None:
    """Change a link's key in place: ``sender`` signs with it, ``receivers`` (one parser per peer)
    check it; None turns signing off on all of them."""
    for codec, sign in ((sender, True), *((r, False) for r in receivers)):
        if key is None:
            codec.signing.secret_key, codec.signing.sign_outgoing = None, False
        else:
            enable_signing(codec, key, sign_outgoing=sign)


def setup_signing_message(key: bytes, sysid: int, compid: int = 1) -> mavlink.MAVLink_message:
    """SETUP_SIGNING giving vehicle ``sysid`` the key ``key`` (NO_KEY: signing off), timestamp now."""
    if len(key) != KEY_BYTES:
        raise ValueError(f"signing key must be {KEY_BYTES} bytes, got {len(key)}")
    timestamp = 0 if key == NO_KEY else signing_timestamp()
    return mavlink.MAVLink_setup_signing_message(sysid, compid, list(key), timestamp)
