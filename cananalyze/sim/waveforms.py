"""Scripted input signals: what a simulated device measures at time t.

Deterministic functions of time (phases drawn from the seeded generator once),
so the same seed gives the same log. Values are raw object values (e.g. 0.1 degC
for a DAT 7014 RTD channel), written into the object dictionary before a PDO is built.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable
from dataclasses import dataclass

Waveform = Callable[[float], int]


@dataclass(frozen=True)
class Drift:
    """A slow sine around base, quantized to step (RTD temperatures, analog inputs)."""

    base: float
    amplitude: float
    period: float
    phase: float = 0.0
    step: int = 1

    def __call__(self, t: float) -> int:
        v = self.base + self.amplitude * math.sin(2 * math.pi * t / self.period + self.phase)
        return int(round(v / self.step)) * self.step


@dataclass(frozen=True)
class Toggle:
    """A byte of digital inputs, bit k flipping every periods[k] seconds."""

    periods: tuple[float, ...]
    offset: float = 0.0

    def __call__(self, t: float) -> int:
        out = 0
        for bit, period in enumerate(self.periods):
            if period > 0 and int((t + self.offset) / period) % 2:
                out |= 1 << bit
        return out


@dataclass(frozen=True)
class Counter:
    """A pulse counter counting at rate per second, wrapping at 2**bits."""

    rate: float
    bits: int = 32

    def __call__(self, t: float) -> int:
        return int(max(t, 0.0) * self.rate) % (1 << self.bits)


@dataclass(frozen=True)
class Override:
    """Another waveform, replaced by a fixed value from t0 to t1 (fault injection)."""

    inner: Waveform
    value: int
    t0: float
    t1: float

    def __call__(self, t: float) -> int:
        return self.value if self.t0 <= t < self.t1 else self.inner(t)


def default_signals(device: str, rng: random.Random) -> dict[tuple[int, int], Waveform]:
    """Waveforms for the inputs of a built-in device; other devices get none."""

    def phase() -> float:
        return rng.uniform(0, 2 * math.pi)

    if device == "dat7014":  # four Pt100 channels in 0.1 degC, drifting slowly
        bases = (215, 232, 187, 254)
        return {
            (0x6401, k + 1): Drift(b, 12, rng.uniform(40, 80), phase()) for k, b in enumerate(bases)
        }
    if device == "dat7130":  # eight digital inputs, eight counters
        sig: dict[tuple[int, int], Waveform] = {
            (0x6000, 1): Toggle((0.7, 1.3, 2.9, 0, 5.1, 0, 0, 11.0), rng.uniform(0, 1)),
        }
        for k in range(8):
            sig[(0x2111, k + 1)] = Counter(rate=(5.0, 2.0, 1.0, 0.5, 0.2, 0.1, 0.05, 0.02)[k])
        return sig
    if device == "mcb560":  # inputs 7-0 and four analog inputs in mV (10 mV steps)
        sig = {(0x6000, 1): Toggle((1.1, 0, 2.3, 0, 0, 4.7, 0, 0), rng.uniform(0, 1))}
        for k, base in enumerate((2500, 5000, 7500, 1200)):
            sig[(0x6401, k + 1)] = Drift(base, 300, rng.uniform(20, 40), phase(), step=10)
        return sig
    if device == "i7231d":  # I-7053 DI bytes and the I-7012 analog input
        return {
            (0x6000, 1): Toggle((0.9, 1.7, 0, 3.3), rng.uniform(0, 1)),
            (0x6000, 2): Toggle((0, 0, 2.1), rng.uniform(0, 1)),
            (0x6401, 1): Drift(16373, 1500, rng.uniform(30, 60), phase(), step=16),
        }
    return {}
