"""Service codes: the CiA 301 service each frame belongs to, as small integers.

Columns of these codes are what the classifier produces; the names are the
`service` values of the JSONL frame records (stable API).
"""

from __future__ import annotations

from enum import IntEnum


class Service(IntEnum):
    OTHER = 0
    NMT = 1
    SYNC = 2
    TIME = 3
    EMCY = 4
    TPDO = 5
    RPDO = 6
    SDO_REQUEST = 7
    SDO_RESPONSE = 8
    HEARTBEAT = 9
    BOOTUP = 10
    GUARD_REQUEST = 11
    GUARD_RESPONSE = 12
    LSS_MASTER = 13
    LSS_SLAVE = 14
    ERROR_FRAME = 15
    # a data frame on 0x701-0x77F that is not 1 byte: not a heartbeat, boot-up or guard
    # response (CiA 301), so it says nothing about any node's state
    ERRCTL_INVALID = 16
    # CiA 304 (protocol/srdo.py): an SRDO's normal and inverted frames (the SRDO number in
    # the classifier's `pdo` column), and the global fail-safe command on 0x001
    SRDO = 17
    SRDO_INVERTED = 18
    GFC = 19
    # CiA 1301 (protocol/usdo.py): a CAN FD frame on an SDO COB-ID of a CANopen FD
    # network, what a USDO client (0x600 + its node-ID) or server (0x580 + its) sends
    USDO_REQUEST = 20
    USDO_RESPONSE = 21

    @property
    def label(self) -> str:
        return SERVICE_NAMES[self]


SERVICE_NAMES: tuple[str, ...] = (
    "other",
    "nmt",
    "sync",
    "time",
    "emcy",
    "tpdo",
    "rpdo",
    "sdo_request",
    "sdo_response",
    "heartbeat",
    "bootup",
    "guard_request",
    "guard_response",
    "lss_master",
    "lss_slave",
    "error_frame",
    "errctl_invalid",
    "srdo",
    "srdo_inverted",
    "gfc",
    "usdo_request",
    "usdo_response",
)

SERVICE_BY_NAME: dict[str, Service] = {name: Service(i) for i, name in enumerate(SERVICE_NAMES)}

# Friendly groupings accepted by `--service` filters.
SERVICE_GROUPS: dict[str, tuple[Service, ...]] = {
    "pdo": (Service.TPDO, Service.RPDO),
    "sdo": (Service.SDO_REQUEST, Service.SDO_RESPONSE, Service.USDO_REQUEST, Service.USDO_RESPONSE),
    "usdo": (Service.USDO_REQUEST, Service.USDO_RESPONSE),
    "errctl": (
        Service.HEARTBEAT,
        Service.BOOTUP,
        Service.GUARD_REQUEST,
        Service.GUARD_RESPONSE,
        Service.ERRCTL_INVALID,  # a filter only: no rule reads this group
    ),
    "guard": (Service.GUARD_REQUEST, Service.GUARD_RESPONSE),
    "lss": (Service.LSS_MASTER, Service.LSS_SLAVE),
    "safety": (Service.SRDO, Service.SRDO_INVERTED, Service.GFC),
}


def parse_services(names: str) -> set[Service]:
    """'sdo,emcy' -> the set of services; raises ValueError naming the unknown one."""
    out: set[Service] = set()
    for raw in names.split(","):
        name = raw.strip().lower().replace("-", "_")
        if not name:
            continue
        if name in SERVICE_BY_NAME:
            out.add(SERVICE_BY_NAME[name])
        elif name in SERVICE_GROUPS:
            out.update(SERVICE_GROUPS[name])
        else:
            known = ", ".join(list(SERVICE_NAMES) + list(SERVICE_GROUPS))
            raise ValueError(f"unknown service {raw!r} (known: {known})")
    return out
