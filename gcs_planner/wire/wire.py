"""MAVLink 2 extension fields that pymavlink 2.4.50's dialect lacks: the mission opaque ids.

The MAVLink XML appended ``opaque_id`` (uint32) to MISSION_COUNT and MISSION_ACK and
``mission_id/fence_id/rally_points_id`` to MISSION_CURRENT as extension fields. Extensions sit after
the base payload and are not part of CRC_EXTRA, so the frames stay compatible with every decoder:
pymavlink simply ignores the extra bytes. We therefore (a) send with subclasses whose ``pack`` appends
the field, and (b) read the field back from the raw frame with :func:`attach_extensions`, which sets
the attribute on the decoded message (0 when absent: "not supported", as the spec says).
"""

from __future__ import annotations

import struct

from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = ["MissionAckMessage", "MissionCountMessage", "MissionCurrentMessage", "attach_extensions"]

_U32 = struct.Struct("<I")
_IDS3 = struct.Struct("<III")
_V2_MAGIC = 0xFD
_V2_HEADER_LEN = 10
# msgid -> (byte offset of the first extension field we add in the payload, field names, struct)
_EXTENSIONS: dict[int, tuple[int, tuple[str, ...], struct.Struct]] = {
    mavlink.MAVLINK_MSG_ID_MISSION_COUNT: (5, ("opaque_id",), _U32),
    mavlink.MAVLINK_MSG_ID_MISSION_ACK: (4, ("opaque_id",), _U32),
    mavlink.MAVLINK_MSG_ID_MISSION_CURRENT: (6, ("mission_id", "fence_id", "rally_points_id"), _IDS3),
}


class MissionCountMessage(mavlink.MAVLink_mission_count_message):
    """MISSION_COUNT with ``opaque_id`` (a download reply tells which plan the vehicle holds)."""

    def __init__(
        self, target_system: int, target_component: int, count: int, mission_type: int = 0, opaque_id: int = 0
    ) -> None:
        super().__init__(target_system, target_component, count, mission_type)
        self.opaque_id = opaque_id
        self._fieldnames = [*self._fieldnames, "opaque_id"]

    def pack(self, mav: mavlink.MAVLink, force_mavlink1: bool = False) -> bytes:
        base = self.unpacker.pack(self.count, self.target_system, self.target_component, self.mission_type)
        return self._pack(
            mav, self.crc_extra, base + _U32.pack(self.opaque_id), force_mavlink1=force_mavlink1
        )


class MissionAckMessage(mavlink.MAVLink_mission_ack_message):
    """MISSION_ACK with ``opaque_id`` (the id of the plan an accepted upload created)."""

    def __init__(
        self, target_system: int, target_component: int, type: int, mission_type: int = 0, opaque_id: int = 0
    ) -> None:
        super().__init__(target_system, target_component, type, mission_type)
        self.opaque_id = opaque_id
        self._fieldnames = [*self._fieldnames, "opaque_id"]

    def pack(self, mav: mavlink.MAVLink, force_mavlink1: bool = False) -> bytes:
        base = self.unpacker.pack(self.target_system, self.target_component, self.type, self.mission_type)
        return self._pack(
            mav, self.crc_extra, base + _U32.pack(self.opaque_id), force_mavlink1=force_mavlink1
        )


class MissionCurrentMessage(mavlink.MAVLink_mission_current_message):
    """MISSION_CURRENT with the three plan ids (mission, fence, rally), streamed by the vehicle."""

    def __init__(
        self,
        seq: int,
        total: int = 0,
        mission_state: int = 0,
        mission_mode: int = 0,
        mission_id: int = 0,
        fence_id: int = 0,
        rally_points_id: int = 0,
    ) -> None:
        super().__init__(seq, total, mission_state, mission_mode)
        self.mission_id = mission_id
        self.fence_id = fence_id
        self.rally_points_id = rally_points_id
        self._fieldnames = [*self._fieldnames, "mission_id", "fence_id", "rally_points_id"]

    def pack(self, mav: mavlink.MAVLink, force_mavlink1: bool = False) -> bytes:
        base = self.unpacker.pack(self.seq, self.total, self.mission_state, self.mission_mode)
        ids = _IDS3.pack(self.mission_id, self.fence_id, self.rally_points_id)
        return self._pack(mav, self.crc_extra, base + ids, force_mavlink1=force_mavlink1)


def attach_extensions(msg: mavlink.MAVLink_message, raw: bytes) -> None:
    """Set the extension attributes of a decoded MISSION_COUNT/ACK/CURRENT from its raw frame.

    MAVLink 2 drops trailing zero bytes of a payload, so a short payload means zeros (unsupported).
    Messages without these extensions are left untouched.
    """
    ext = _EXTENSIONS.get(msg.get_msgId())
    if ext is None:
        return
    offset, names, codec = ext
    payload = b""
    if raw and raw[0] == _V2_MAGIC:
        payload = bytes(raw[_V2_HEADER_LEN : _V2_HEADER_LEN + raw[1]])
    chunk = payload[offset : offset + codec.size].ljust(codec.size, b"\x00")
    for name, value in zip(names, codec.unpack(chunk), strict=True):
        setattr(msg, name, value)
    msg._fieldnames = [*msg._fieldnames, *(n for n in names if n not in msg._fieldnames)]
