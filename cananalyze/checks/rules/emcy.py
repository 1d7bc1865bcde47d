"""EMCY: each error raised and cleared, inhibit time 0x1015, errors still active at the end.

EMCY frames are rare, so this walks them one by one and keeps the active set per node.
"""

from __future__ import annotations

import numpy as np

from ...protocol.emcy import MIN_BYTES, SIZE, decoded_words, error_text, register_text
from ...protocol.services import Service
from ..columns import FindingColumns
from ..rule import Context, Rule, ms
from ..spans import crossing, per_frame


class EmcyRule(Rule):
    name = "emcy"
    timing = False  # judged by frame order: kept on logs without timestamps
    severity = "warning"
    why = (
        "The node reported an error condition; read the error code and register, and the "
        "manufacturer bytes' meaning (in brackets when the node's profile knows it, else "
        "in the device manual)."
    )

    def __init__(self, allow: list[int] | None = None, **kw) -> None:
        super().__init__(**kw)
        self.allow = {int(c) for c in allow or []}
        self.active: dict[int, dict[int, float]] = {}
        self.last_t: dict[int, float] = {}
        self.words: dict[tuple[int, int], str] = {}  # (node, code) -> the device's meaning

    def process(self, ctx: Context) -> None:
        """Columns per batch; Python only per node and per finding actually listed.

        The findings are the same, in the same order, as walking the EMCY frames one by
        one: each frame may give an inhibit-time, a length and an error finding (in that
        order), counted against the node's cap in frame order.
        """
        b = ctx.batch
        rows = np.flatnonzero(b.service == Service.EMCY)
        if rows.size == 0:
            return
        fb = b.frames
        node = b.node[rows].astype(np.int64)
        t = fb.t[rows]
        dlc = fb.dlc[rows].astype(np.int64)
        head = fb.data[rows, :3].astype(np.int64)
        code = head[:, 0] | (head[:, 1] << 8)
        reg = head[:, 2]
        uniq, first = np.unique(node, return_index=True)
        seen = np.argsort(first, kind="stable")  # nodes in the order their first EMCY came
        nodes = uniq[seen].tolist()
        for n in nodes:
            self.subjects.add(n)
        # previous EMCY of the same node (carried across batches) and 0x1015 per node
        srt = np.argsort(node, kind="stable")
        ns, ts = node[srt], t[srt]
        head_of = np.ones(ns.size, bool)
        head_of[1:] = ns[1:] != ns[:-1]
        prev_s = np.empty_like(ts)
        prev_s[1:] = ts[:-1]
        prev_s[head_of] = [self.last_t.get(n, np.nan) for n in ns[head_of].tolist()]
        prev = np.empty_like(t)
        prev[srt] = prev_s
        inhibit = np.zeros(node.size, np.float64)
        across = np.zeros(node.size, bool)
        for j in seen.tolist():  # 0x1015 in force at each EMCY: one lookup per stretch
            n = int(uniq[j])
            at = np.flatnonzero(node == n)
            changes = ctx.config.changes(n, 0x1015, 0x1015)
            inhibit[at] = per_frame(
                changes, t[at], lambda x, n=n: ctx.config.emcy_inhibit_100us(n, x) or 0
            )
            across[at] = crossing(changes, prev[at], t[at])
        with np.errstate(invalid="ignore"):
            fast = (
                ctx.timed
                & ~np.isnan(prev)
                & ~across
                & (inhibit != 0)
                & ((t - prev) < inhibit * 1e-4 * (1 - self.tolerance))
            )
        short = dlc < SIZE
        raised = (dlc >= MIN_BYTES) & (code != 0)
        if self.allow:
            raised &= ~np.isin(code, np.fromiter(self.allow, np.int64))
        last_row = np.full(uniq.size, -1, np.int64)
        np.maximum.at(last_row, np.searchsorted(uniq, node), np.arange(node.size))
        for j in seen.tolist():
            self.last_t[int(uniq[j])] = float(t[last_row[j]])
        self._active(node, uniq, seen, t, dlc, code, reg)
        self._findings(ctx, rows, node, t, dlc, code, reg, prev, inhibit, fast, short, raised)

    def _active(self, node, uniq, seen, t, dlc, code, reg) -> None:
        """Errors active per node after this batch: those raised since the last reset."""
        for j in seen.tolist():
            n = int(uniq[j])
            at = np.flatnonzero((node == n) & (dlc >= MIN_BYTES))
            if at.size == 0:
                continue
            act = self.active.setdefault(n, {})
            c, r = code[at], reg[at]
            reset = np.flatnonzero((c == 0) & (r == 0))
            if reset.size:
                act.clear()
                at = at[reset[-1] + 1 :]
                c = c[reset[-1] + 1 :]
            raised = c != 0
            act.update(zip(c[raised].tolist(), t[at[raised]].tolist(), strict=True))

    def _findings(self, ctx, rows, node, t, dlc, code, reg, prev, inhibit, fast, short, raised):
        """Emit the findings still under each node's cap, count the others, in frame order."""
        pos = np.concatenate((np.flatnonzero(fast), np.flatnonzero(short), np.flatnonzero(raised)))
        if pos.size == 0:
            return
        kind = np.repeat([0, 1, 2], [int(fast.sum()), int(short.sum()), int(raised.sum())])
        seq = np.lexsort((kind, pos))  # frame order, then inhibit / length / error
        pos, kind = pos[seq], kind[seq]
        cn = node[pos]
        by = np.argsort(cn, kind="stable")
        cs = cn[by]
        start = np.ones(cs.size, bool)
        start[1:] = cs[1:] != cs[:-1]
        group_start = np.maximum.accumulate(np.where(start, np.arange(cs.size), 0))
        rank = np.empty(cs.size, np.int64)
        rank[by] = np.arange(cs.size) - group_start
        firsts = np.unique(cn, return_index=True)[1]
        left = {}
        for i in np.sort(firsts).tolist():  # the cap's counters, keyed in first-finding order
            n = int(cn[i])
            key = (n, 0x80 + n)
            self._count[key] += 0
            left[n] = max(self.max_findings - self._count[key], 0)
        listed = rank < np.array([left[n] for n in cn.tolist()], np.int64)
        self._emit_listed(ctx, rows, pos[listed], kind[listed], node, t, dlc, code, reg, prev,
                          inhibit)  # fmt: skip
        dropped = np.flatnonzero(~listed)
        if dropped.size:
            dn = cn[dropped]
            for n, first_i, count in zip(
                *[x.tolist() for x in np.unique(dn, return_index=True, return_counts=True)],
                strict=True,
            ):
                key = (n, 0x80 + n)
                self._count[key] += count
                self._first_dropped.setdefault(key, float(t[pos[dropped[first_i]]]))

    def _emit_listed(self, ctx, rows, ks, kinds, node, t, dlc, code, reg, prev, inhibit) -> None:
        """The findings listed, in frame order, as one block of columns: an inhibit-time
        (kind 0), a length (1) or an error (2) finding per entry; the errors' texts are
        built when read."""
        m = ks.size
        if m == 0:
            return
        nodes = node[ks]
        for n, c in zip(*np.unique(nodes, return_counts=True), strict=True):
            self._count[(int(n), 0x80 + int(n))] += int(c)
        kl, nl, tl = kinds.tolist(), nodes.tolist(), t[ks].tolist()
        frame_rows = rows[ks]
        cl, rl = code[ks].tolist(), reg[ks].tolist()
        measured: list = [None] * m
        expected: list = [None] * m
        severity: list = [self.severity] * m
        why: list = [self.why] * m
        basis: list = [""] * m
        fixed: dict[int, str] = {}  # texts of the rare inhibit and length findings
        words = [""] * m
        allowed = (
            "no EMCY"
            if not self.allow
            else "one of " + ", ".join(f"0x{x:04X}" for x in sorted(self.allow))
        )
        notes = ctx.batch.notes
        for j, kind in enumerate(kl):
            n, tk = nl[j], tl[j]
            if kind == 0:
                k = int(ks[j])
                gap = tk - float(prev[k])
                inh = float(inhibit[k])  # int or float as configured: the same products
                fixed[j] = (
                    f"EMCY {ms(gap)} ms after the previous one, inhibit "
                    f"time 0x1015 is {inh * 0.1:g} ms"
                )
                measured[j], expected[j], severity[j] = ms(gap), inh * 0.1, "error"
                basis[j] = ctx.config.origin(n, 0x1015, 0, tk, ctx.t0)
                why[j] = (
                    "EMCY faster than its inhibit time can flood the bus in a fault storm; check 0x1015."
                )
            elif kind == 1:
                d = int(dlc[ks[j]])
                fixed[j] = f"EMCY with {d} data bytes, CiA 301 needs {SIZE}"
                measured[j], expected[j], severity[j] = d, SIZE, "error"
                why[j] = (
                    "A short EMCY cannot be decoded by a standard master; check the node's firmware."
                )
            else:
                c = cl[j]
                decoded = notes.get(int(frame_rows[j]), {}).get("manufacturer_decoded")
                w = f" ({decoded_words(decoded)})" if decoded else ""
                if w:
                    self.words[(n, c)] = words[j] = w
                else:
                    self.words.pop((n, c), None)
                measured[j], expected[j] = f"0x{c:04X}", allowed

        def text(idx: np.ndarray) -> list[str]:
            return [
                fixed[j]
                if j in fixed
                else f"EMCY {error_text(cl[j])}; {register_text(rl[j])}{words[j]}"
                for j in idx.tolist()
            ]

        self.emit_rows(
            FindingColumns.block(
                self.name,
                severity,
                tl,
                nodes,
                nodes + 0x80,
                text,
                measured,
                expected,
                why,
                frame_rows,
                basis,
            )  # fmt: skip
        )

    def finish(self, ctx: Context) -> None:
        """Errors still active, per node by code, as columns (a node raising one EMCY
        after another without a reset leaves hundreds)."""
        rel = ctx.rel
        for node, act in sorted(self.active.items()):
            codes = [c for c in sorted(act) if c not in self.allow]
            if not codes:
                continue
            times = [act[c] for c in codes]
            words = [self.words.get((node, c), "") for c in codes]

            def text(idx: np.ndarray, codes=codes, times=times, words=words) -> list[str]:
                return [
                    f"EMCY {error_text(codes[j])}{words[j]} raised at {rel(times[j])} "
                    "still active at the end of the log"
                    for j in idx.tolist()
                ]

            self.emit_many(
                np.array(times, np.float64),
                node,
                0x80 + node,
                text,
                [f"0x{c:04X}" for c in codes],
                "cleared",
                why="No error reset (EMCY 0x0000) followed; the node may still be in its fault "
                "reaction; check whether the cause was removed.",
            )

    def active_errors(self) -> dict[int, list[int]]:
        return {n: sorted(a) for n, a in self.active.items() if a}
