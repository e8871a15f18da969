"""MAVLink 2 message signing, shared by the GCS link and the mock vehicles.

A signed link appends to every frame a 13-byte block: link id, a 48-bit timestamp (10 us units since
2015-01-01) and the first 6 bytes of SHA-256(key + frame). Autopilots with signing enabled
(ArduPilot, PX4) ignore unsigned commands, so a field GCS must sign. pymavlink packs the signed
frames; the timestamps and the checks on receipt are signing_streams.py's (pymavlink's own check
has the flaws listed there). ``LinkSigning`` is one link's signing: key, clock, replay table.

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

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.wire.signing_streams import SignatureVerifier, SigningClock, signing_timestamp

__all__ = [
    "KEY_BYTES",
    "NO_KEY",
    "LinkSigning",
    "key_from_passphrase",
    "setup_signing_message",
    "signing_timestamp",
]

KEY_BYTES = 32
NO_KEY = bytes(KEY_BYTES)  # with timestamp 0 in SETUP_SIGNING: turn signing off (ArduPilot's convention)


def key_from_passphrase(passphrase: str) -> bytes:
    """The 32-byte signing key of a passphrase (SHA-256, as MAVProxy and QGroundControl)."""
    if not passphrase:
        raise ValueError("signing passphrase must not be empty")
    return hashlib.sha256(passphrase.encode()).digest()


def _check_key(key: bytes) -> None:
    if len(key) != KEY_BYTES:
        raise ValueError(f"signing key must be {KEY_BYTES} bytes, got {len(key)}")


class LinkSigning:
    """The signing of one link: ``codec`` (the link's sending pymavlink object) signs with the key
    and a timestamp from ``clock``; ``accept`` checks received frames against one replay table for
    all the link's peers. No key: frames go out unsigned and every frame is accepted."""

    def __init__(self, codec: mavlink.MAVLink, key: bytes | None = None, link_id: int = 0) -> None:
        self.codec = codec
        self.link_id = link_id
        self.clock = SigningClock()
        self.verifier: SignatureVerifier | None = None
        self._streams: dict[tuple[int, int, int], int] = {}  # kept across key changes
        self.set_key(key)

    @property
    def key(self) -> bytes | None:
        return None if self.verifier is None else self.verifier.key

    def set_key(self, key: bytes | None) -> None:
        """Sign and verify with ``key`` from now on (None: neither)."""
        signing = self.codec.signing
        if key is None:
            self.verifier = None
            signing.secret_key, signing.sign_outgoing = None, False
            return
        _check_key(key)
        self.verifier = SignatureVerifier(key, self.clock)
        self.verifier.streams = self._streams
        signing.secret_key, signing.sign_outgoing, signing.link_id = key, True, self.link_id

    def pack(self, msg: mavlink.MAVLink_message) -> bytes:
        """``msg`` packed by the codec, signed with the next timestamp when there is a key."""
        if self.verifier is not None:
            self.codec.signing.timestamp = self.clock.next()
        return msg.pack(self.codec)

    def sign(self, frame: bytes) -> bytes:
        """``frame`` (codec.frame with the SIGNED flag, a key set) with its signature block, the next
        timestamp: what ``pack`` makes of the same message, without a message object."""
        assert self.verifier is not None, "sign needs a key"
        block = self.link_id.to_bytes(1, "little") + self.clock.next().to_bytes(6, "little")
        return frame + block + hashlib.sha256(self.verifier.key + frame + block).digest()[:6]

    def accept(self, frame: bytes) -> bool:
        """True when no key is set, or ``frame`` verifies and is newer than its stream."""
        return self.verifier is None or self.verifier.accept(frame)


def setup_signing_message(key: bytes, sysid: int, compid: int = 1) -> mavlink.MAVLink_setup_signing_message:
    """SETUP_SIGNING giving vehicle ``sysid`` the key ``key`` (NO_KEY: signing off), timestamp now."""
    _check_key(key)
    timestamp = 0 if key == NO_KEY else signing_timestamp()
    return mavlink.MAVLink_setup_signing_message(sysid, compid, list(key), timestamp)
