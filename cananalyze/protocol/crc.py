"""CRC-16 CCITT (polynomial 0x1021, initial 0): SDO block transfers (CiA 301 7.2.4.3.16) and
SRDO configuration signatures (CiA 304: CANopenNode's 301/crc16-ccitt.c, used by 304/CO_SRDO.c).

Hand-written because it is six lines; canopen keeps its own copy private.
"""

from __future__ import annotations


def crc16(data: bytes, crc: int = 0) -> int:
    """CRC-16/XMODEM over data, continuing from crc."""
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else crc << 1
            crc &= 0xFFFF
    return crc
