"""Hypothesis strategies for hostile frames and mutated log bytes.

Frames favour what breaks decoders: CANopen identifiers (each service's range),
SDO command bytes, empty and over-long payloads, every flag combination.
Mutations are what damaged files look like: bit flips, inserted and deleted
bytes, truncation, swapped lines.
"""

from __future__ import annotations

from hypothesis import strategies as st

from cananalyze.core.frames import (
    FLAG_BRS,
    FLAG_ERR,
    FLAG_ESI,
    FLAG_EXT,
    FLAG_FD,
    FLAG_RTR,
    FLAG_TX,
    FrameBatch,
    from_rows,
)

_FLAGS = (FLAG_EXT, FLAG_RTR, FLAG_ERR, FLAG_FD, FLAG_BRS, FLAG_ESI, FLAG_TX)

# identifiers near every predefined-connection-set range and its edges
canopen_ids = st.one_of(
    st.sampled_from([0x000, 0x080, 0x100, 0x700, 0x7E4, 0x7E5, 0x7FF, 0x64B, 0x5CB]),
    st.integers(0, 0x7F).map(lambda n: n | st_choice_base(n)),
    st.integers(0, 0x7FF),
    st.integers(0, 0x1FFFFFFF),
)


def st_choice_base(n: int) -> int:
    return (0x080, 0x180, 0x200, 0x280, 0x300, 0x380, 0x400, 0x480, 0x500, 0x580, 0x600, 0x700)[
        n % 12
    ]


sdo_payloads = st.builds(
    lambda cmd, rest: bytes([cmd]) + rest,
    st.sampled_from(
        [
            0x20,
            0x21,
            0x22,
            0x23,
            0x2B,
            0x2F,
            0x40,
            0x42,
            0x43,
            0x4F,
            0x60,
            0x80,
            0x00,
            0x10,
            0x11,
            0xA0,
            0xA1,
            0xA2,
            0xA4,
            0xC0,
            0xC1,
            0xC2,
            0xC4,
            0xC6,
            0xE0,
            0x41,
            0x4B,
            0x01,
            0x81,
            0x7F,
        ]
    ),
    st.binary(min_size=0, max_size=7),
)

payloads = st.one_of(
    st.binary(min_size=0, max_size=8), sdo_payloads, st.binary(min_size=9, max_size=64)
)

frame_rows = st.tuples(
    st.one_of(st.floats(0, 1e10, allow_nan=False), st.floats(-1.0, 5.0, allow_nan=False)),
    canopen_ids,
    payloads,
    st.integers(0, 127).map(lambda m: sum(f for i, f in enumerate(_FLAGS) if m >> i & 1)),
    st.integers(0, 2),
)


def make_batch(rows: list[tuple], sort: bool = False) -> FrameBatch:
    """FrameBatch from hypothesis rows (times may go backwards unless sort)."""
    if sort:
        rows = sorted(rows, key=lambda r: r[0])
    return from_rows(rows, channels=("can0", "can1", "vcan2"))


@st.composite
def mutated(draw, data: bytes, max_ops: int = 4) -> bytes:
    """`data` damaged by a few operations a broken copy or logger could cause."""
    buf = bytearray(data)
    for _ in range(draw(st.integers(1, max_ops))):
        op = draw(st.sampled_from(["flip", "insert", "delete", "truncate", "set", "swap", "dup"]))
        if not buf:
            buf += b"\n"
        pos = draw(st.integers(0, len(buf) - 1))
        if op == "flip":
            buf[pos] ^= 1 << draw(st.integers(0, 7))
        elif op == "insert":
            buf[pos:pos] = draw(st.binary(min_size=1, max_size=16))
        elif op == "delete":
            del buf[pos : pos + draw(st.integers(1, 32))]
        elif op == "truncate":
            del buf[pos:]
        elif op == "set":
            buf[pos] = draw(st.sampled_from(b"0123456789abcdefxyzR#().;,: \n\r\t\x00\xff\xb3-"))
        elif op == "swap":
            lines = bytes(buf).split(b"\n")
            i, j = draw(st.integers(0, len(lines) - 1)), draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
            buf = bytearray(b"\n".join(lines))
        else:
            start = draw(st.integers(0, len(buf) - 1))
            buf[pos:pos] = buf[start : start + draw(st.integers(1, 200))]
    return bytes(buf)


def fuzz_settings(examples: int):
    """CI: `examples` derandomized (same inputs every run). Campaign: CANANALYZE_FUZZ=N multiplies
    the budget and draws fresh random inputs."""
    import os

    from hypothesis import HealthCheck, settings

    scale = int(os.environ.get("CANANALYZE_FUZZ", "0") or 0)
    return settings(
        max_examples=examples * scale if scale else examples,
        deadline=None,
        derandomize=not scale,
        database=None,
        suppress_health_check=[
            HealthCheck.too_slow,
            HealthCheck.data_too_large,
            HealthCheck.filter_too_much,
        ],
    )
