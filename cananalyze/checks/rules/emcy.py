"""EMCY: each error raised and cleared, inhibit time 0x1015, errors still active at the end.

EMCY frames are rare, so this walks them one by one and keeps the active set per node.
"""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule, ms
from cananalyze.checks.spans import crossing, per_frame
from cananalyze.core.finding_columns import FindingColumns, objects
from cananalyze.protocol.emcy import (
    MIN_BYTES,
    SIZE,
    code_texts,
    decoded_words,
    error_lines,
    error_text,
)
from cananalyze.protocol.services import Service


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
        rows = ctx.rows(Service.EMCY)
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
        cut = np.append(np.flatnonzero(head_of), ns.size)
        groups = [srt[a:b] for a, b in zip(cut[:-1].tolist(), cut[1:].tolist(), strict=True)]
        inhibit = np.zeros(node.size, np.float64)
        across = np.zeros(node.size, bool)
        for j in seen.tolist():  # 0x1015 in force at each EMCY: one lookup per stretch
            n, at = int(uniq[j]), groups[j]  # the node's EMCYs, in frame order
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
        last_row = srt[cut[1:] - 1]  # each node's last EMCY
        for j in seen.tolist():
            self.last_t[int(uniq[j])] = float(t[last_row[j]])
        self._active(groups, uniq, seen, t, dlc, code, reg)
        self._findings(ctx, rows, node, t, dlc, code, reg, prev, inhibit, fast, short, raised)

    def _active(self, groups, uniq, seen, t, dlc, code, reg) -> None:
        """Errors active per node after this batch: those raised since the last reset
        (`groups`: each node's EMCYs in frame order, nodes as in `uniq`)."""
        for j in seen.tolist():
            n, at = int(uniq[j]), groups[j]
            at = at[dlc[at] >= MIN_BYTES]
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
        (kind 0), a length (1) or an error (2) finding per entry. The errors (a fault
        storm lists tens of thousands) are columns; only the rare others are walked. The
        errors' texts are built when read, once per distinct code and register."""
        m = ks.size
        if m == 0:
            return
        nodes = node[ks]
        for n, c in zip(*np.unique(nodes, return_counts=True), strict=True):
            self._count[(int(n), 0x80 + int(n))] += int(c)
        frame_rows = rows[ks]
        codes, regs = code[ks], reg[ks]
        err = np.flatnonzero(kinds == 2)
        severity, why, basis = objects(self.severity, m), objects(self.why, m), objects("", m)
        measured = np.empty(m, object)
        expected = np.empty(m, object)
        measured[err] = code_texts(codes[err])
        expected[err] = (
            "no EMCY"
            if not self.allow
            else "one of " + ", ".join(f"0x{x:04X}" for x in sorted(self.allow))
        )
        words = self._words(ctx, err, nodes, codes, frame_rows, m)
        fixed = np.empty(m, object)  # texts of the rare inhibit and length findings
        for j in np.flatnonzero(kinds != 2).tolist():
            k, n, tk = int(ks[j]), int(nodes[j]), float(t[ks[j]])
            severity[j] = "error"
            if kinds[j] == 0:
                gap = tk - float(prev[k])
                inh = float(inhibit[k])  # int or float as configured: the same products
                fixed[j] = (
                    f"EMCY {ms(gap)} ms after the previous one, inhibit "
                    f"time 0x1015 is {inh * 0.1:g} ms"
                )
                measured[j], expected[j] = ms(gap), inh * 0.1
                basis[j] = ctx.config.origin(n, 0x1015, 0, tk, ctx.t0)
                why[j] = (
                    "EMCY faster than its inhibit time can flood the bus in a fault storm; check 0x1015."
                )
            else:
                d = int(dlc[k])
                fixed[j] = f"EMCY with {d} data bytes, CiA 301 needs {SIZE}"
                measured[j], expected[j] = d, SIZE
                why[j] = (
                    "A short EMCY cannot be decoded by a standard master; check the node's firmware."
                )
        is_fixed = np.not_equal(fixed, None)

        def text(idx: np.ndarray) -> np.ndarray:
            out = error_lines(codes[idx], regs[idx])
            if words is not None:
                out += words[idx]
            own = is_fixed[idx]
            out[own] = fixed[idx[own]]
            return out

        self.emit_rows(
            FindingColumns.block(
                self.name,
                severity,
                t[ks],
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

    def _words(self, ctx, err, nodes, codes, frame_rows, m: int) -> np.ndarray | None:
        """The errors' ' (meaning of the vendor bytes)' where the node's profile reads them
        (None: none has one), and each (node, code)'s latest in `self.words` for the
        errors still active at the end."""
        # the dict's own methods, not the notes': `LazyNotes` would check per row whether
        # a pending SDO writer covers it; those write SDO notes only, and the profile's
        # readings (EmcyDecoder) are in the dict already. The rows with a note are
        # found among the dict's keys (a few per batch), not looked up per error.
        notes = ctx.batch.notes
        keys = np.fromiter(dict.keys(notes), np.int64, dict.__len__(notes))
        at = frame_rows[err]
        decoded: list = [None] * err.size
        for j in np.flatnonzero(np.isin(at, keys)).tolist():
            decoded[j] = dict.get(notes, int(at[j])).get("manufacturer_decoded")
        if not any(decoded) and not self.words:
            return None
        words = np.full(m, "", object)
        for j, d in zip(err.tolist(), decoded, strict=True):
            key = (int(nodes[j]), int(codes[j]))
            if d:
                self.words[key] = words[j] = f" ({decoded_words(d)})"
            else:
                self.words.pop(key, None)
        return words if any(decoded) else None

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
