"""The EMCY rule, now columnar per batch, lists and counts exactly what the per-frame walk did.

The reference below is the former rule (one Python iteration per EMCY frame). Random
EMCY storms (short frames, resets, repeated codes, a fast inhibit time, an allow list,
tight caps) are checked in several batch sizes: findings, their order, the capped
counts, subjects and the active errors must be the same.
"""

from __future__ import annotations

import numpy as np
import pytest

from cananalyze.checks.engine import Checker
from cananalyze.checks.rule import Context, Rule, ms
from cananalyze.checks.rules.emcy import EmcyRule
from cananalyze.core.frames import from_rows
from cananalyze.pipeline import Decoder
from cananalyze.protocol.emcy import error_text, register_text
from cananalyze.protocol.services import Service


class ReferenceEmcyRule(EmcyRule):
    """The per-frame rule as it was (findings formatted only under the cap)."""

    def process(self, ctx: Context) -> None:
        b = ctx.batch
        rows = np.flatnonzero(b.service == Service.EMCY)
        if rows.size == 0:
            return
        fb = b.frames
        nodes = b.node[rows].tolist()
        times = fb.t[rows].tolist()
        dlcs = fb.dlc[rows].tolist()
        head = fb.data[rows, :3].tolist()
        inhibits: dict[int, int] = {}
        for k, row in enumerate(rows.tolist()):
            node, t, dlc = nodes[k], times[k], dlcs[k]
            self.subjects.add(node)
            prev = self.last_t.get(node)
            self.last_t[node] = t
            inhibit = inhibits.get(node)
            if inhibit is None:
                inhibit = inhibits[node] = ctx.config.emcy_inhibit_100us(node, t) or 0
            if prev is not None and inhibit and t - prev < inhibit * 1e-4 * (1 - self.tolerance):
                self.emit(t, node, 0x80 + node,
                          f"EMCY {ms(t - prev)} ms after the previous one, inhibit "
                          f"time 0x1015 is {inhibit * 0.1:g} ms",
                          ms(t - prev), inhibit * 0.1, row=row, severity="error",
                          why="EMCY faster than its inhibit time can flood the bus in a fault "
                          "storm; check 0x1015.",
                          basis=ctx.config.origin(node, 0x1015, 0, t, ctx.t0))  # fmt: skip
            if dlc < 8:
                self.emit(t, node, 0x80 + node, f"EMCY with {dlc} data bytes, CiA 301 needs 8",
                          dlc, 8, row=row, severity="error",
                          why="A short EMCY cannot be decoded by a standard master; check the "
                          "node's firmware.")  # fmt: skip
                if dlc < 3:
                    continue
            b0, b1, reg = head[k]
            code = b0 | b1 << 8
            act = self.active.setdefault(node, {})
            if code == 0:
                if reg == 0:
                    act.clear()
                continue
            act[code] = t
            if code in self.allow:
                continue
            self.emit(t, node, 0x80 + node,
                      f"EMCY {error_text(code)}; {register_text(reg)}",
                      f"0x{code:04X}",
                      "no EMCY" if not self.allow
                      else "one of " + ", ".join(f"0x{c:04X}" for c in sorted(self.allow)),
                      row=row)  # fmt: skip


class _Inhibit:
    """Config stub: 0x1015 per node (node 2: 1.0 ms, node 3: 2.5 ms, others none)."""

    def __getattr__(self, name):
        return lambda *a, **k: None

    def emcy_inhibit_100us(self, node, t):
        return {2: 10, 3: 25.0}.get(node)

    def changes(self, node, first, last):
        return np.zeros(0)  # the same all through the log


def _storm(seed: int):
    rng = np.random.default_rng(seed)
    rows, t = [], 0.0
    for _ in range(int(rng.integers(50, 400))):
        t += float(rng.choice([0.0001, 0.0007, 0.002, 0.05]))
        node = int(rng.integers(1, 6))
        code = int(rng.choice([0, 0x1000, 0x2310, 0x8130, 0xFF01]))
        reg = int(rng.choice([0, 0x01, 0x11]))
        data = bytes([code & 0xFF, code >> 8, reg, 1, 2, 3, 4, 5])[
            : int(rng.choice([8, 8, 8, 5, 2, 0]))
        ]
        rows.append((t, 0x80 + node, data))
        if rng.random() < 0.05:
            rows.append((t + 1e-5, 0x700 + node, b"\x05"))
    return from_rows(rows)


def _run(cls, fb, step: int, allow, cap: int):
    rule: Rule = cls(allow=allow)
    rule.max_findings = cap
    checker = Checker(rules=[rule], config=_Inhibit())
    dec = Decoder([checker])
    for s in range(0, len(fb), step):
        dec.decode(fb.take(slice(s, s + step)))
    dec.finish()
    return (
        [f.record() for f in checker.findings],
        dict(rule._count),
        rule._first_dropped,
        sorted(rule.subjects),
        list(rule.last_t.items()),
        {n: sorted(a.items()) for n, a in rule.active.items() if a},
    )


@pytest.mark.parametrize("seed", range(12))
def test_same_findings_as_the_per_frame_walk(seed: int) -> None:
    fb = _storm(seed)
    for step, allow, cap in ((1 << 20, None, 20), (37, [0x1000], 3), (5, None, 0), (101, [], 1000)):
        assert _run(EmcyRule, fb, step, allow, cap) == _run(
            ReferenceEmcyRule, fb, step, allow, cap
        ), (step, allow, cap)
