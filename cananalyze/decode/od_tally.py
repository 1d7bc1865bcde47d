"""Each node's object dictionary as the log showed it: the values of successful SDO transfers.

A log shows much of a network's configuration: every SDO upload that answered and
every download that was confirmed. This follows them batch by batch, per bus (the frame's
channel), node, index and sub-index, in the order the transfers ended: the last value, when and how it
was set (read or written), how often, and the values it went through. A boot-up of
the node starts a new life (its objects are back to their defaults unless stored), so a
value is kept per life: `life` counts the node's boot-ups before the transfer.

PDO-mapped objects (issue 41): where a PDO's mapping is known (the log's 0x1600/0x1A00
writes, the network file, the device's profile), each mapped object's last value in each
life is a row too, named and decoded by the mapping, `set_by` "pdo", its frames counted
as `transfers`. An object both an SDO transfer and a PDO showed in a life has the row of
the later (by frame, so on a log without times too): its last value. PDO rows are process
data, not configuration: no DCF holds them and `diff` does not compare them.

`load().od`, the export's `od` table, `cananalyze od` and its DCFs all read `rows()`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cananalyze.core.columns.numtext import scalar_text
from cananalyze.core.records import DecodedBatch
from cananalyze.protocol.services import Service

HISTORY = 16  # values kept per object and life: the first ones and the last one
OD_COLUMNS = (
    "node",
    "index",
    "subindex",
    "life",
    "name",
    "value",
    "data",
    "size",
    "words",
    "t",
    "set_by",
    "t_first",
    "transfers",
    "changes",
    "history",
)


@dataclass
class _Object:
    """One object of one node in one life, as the transfers showed it."""

    t_first: float
    key: object  # the last transfer's bytes, comparable (`_data_keys`)
    rec: dict | None = None  # the last transfer's record (built at the end of its batch)
    transfers: int = 1
    changes: int = 0
    history: list = field(default_factory=list)  # the first values, as shown
    more: bool = False  # more changes than the history keeps
    row: int = -1  # the last transfer's frame, counted from the log's first


@dataclass
class _Mapped:
    """One PDO-mapped object of one node in one life, as the PDO frames carried it."""

    name: str
    t_first: float
    t: float
    last: object  # the last value (a Python scalar)
    unit: str | None
    frames: int = 0
    changes: int = 0
    history: list = field(default_factory=list)
    more: bool = False
    row: int = -1  # the last frame's, counted from the log's first


class OdTally:
    """Per bus, node, life and object: what the successful SDO transfers showed.

    A polled bus repeats the same reads: only the first transfer of an object, each
    change while the history has room, and the last of each batch are read as records
    (on the fast path's columns the others are compared by their bytes, not built)."""

    def __init__(self) -> None:
        self.objects: dict[tuple, _Object] = {}  # (bus, node, life, index, sub) -> object
        self.mapped: dict[tuple, _Mapped] = {}  # the same keys -> a PDO-mapped object
        self.lives: dict[tuple, int] = {}  # (bus, node) -> boot-ups seen so far
        self.boot_t: dict[tuple, list[float]] = {}  # (bus, node) -> boot-up times
        self.several = False  # frames of more than one channel seen: rows name their bus
        self.offset = 0  # frames of the batches before (orders SDO and PDO of a log untimed)
        self._off = 0
        self._first: str | None = None

    def add(self, batch: DecodedBatch) -> None:
        """One batch's boot-ups and successful SDO transfers, in row order (a transfer
        ending on a boot-up's row is before it: the answer came first)."""
        fb = batch.frames
        self._off = self.offset
        self.offset += len(fb)
        if len(fb) and not self.several:
            first = fb.channel_label(int(fb.channel[0]))
            self._first = self._first or first
            self.several = first != self._first or bool((fb.channel != fb.channel[0]).any())
        boot = batch.service == np.uint8(Service.BOOTUP)
        boots = np.flatnonzero(boot) if boot.any() else np.zeros(0, np.int64)
        recs = batch.records
        at = np.zeros(0, np.int64)
        if recs:
            c = recs.cols
            at = np.flatnonzero(c.ok & (c.node >= 0) & (c.index >= 0) & (c.subindex >= 0))
        blocks = [b for b in batch.signals if b.objects and len(b.rows) and "pdo" in b.pdo]
        if not boots.size and not at.size and not blocks:
            return
        top = int(fb.channel.max()) + 1 if len(fb) else 1
        labels = [fb.channel_label(c) for c in range(top)]
        boot_ch = fb.channel[boots].astype(np.int64) if len(fb) else boots
        boot_node = batch.node[boots].astype(np.int64)
        if at.size:
            self._transfers(batch, at, labels, boots, boot_ch, boot_node)
        if blocks:
            self._mapped(fb, blocks, labels, boots, boot_ch, boot_node)
        for row, ch, node in zip(boots.tolist(), boot_ch.tolist(), boot_node.tolist(), strict=True):
            key = (labels[ch], node)
            self.lives[key] = self.lives.get(key, 0) + 1
            self.boot_t.setdefault(key, []).append(float(fb.t[row]))

    def _transfers(self, batch, at, labels, boots, boot_ch, boot_node) -> None:
        """The batch's successful transfers, grouped by object with numpy: per group one
        step here, the records read only for what is shown (first, changes, last)."""
        fb, recs = batch.frames, batch.records
        c = recs.cols
        rows = c.row[at]  # the records' rows (`recs.rows`), as a column
        node, index, sub = c.node[at], c.index[at], c.subindex[at]
        if len(fb) and int(fb.channel.max()) == int(fb.channel.min()):  # one bus: no gather
            ch = np.where(rows < len(fb), np.int64(fb.channel[0]), np.int64(0))
        else:
            ch = np.zeros(len(at), np.int64)
            inside = rows < len(fb)
            ch[inside] = fb.channel[rows[inside]]
        # each transfer's life: the node's before this batch, plus its boot-ups before it
        pair = ch * 256 + node
        if node.size and int(node.max()) < 256 and int(pair.max()) < 1 << 16:
            # (few small pairs: the distinct ones by a count, each value by a lookup)
            uniq = np.flatnonzero(np.bincount(pair))
            before = np.zeros(int(uniq[-1]) + 1, np.int64)
            before[uniq] = [self.lives.get((labels[p // 256], p % 256), 0) for p in uniq.tolist()]
            life = before[pair]
        else:
            uniq, inv = np.unique(pair, return_inverse=True)
            before = [self.lives.get((labels[p // 256], int(p % 256)), 0) for p in uniq.tolist()]
            life = np.asarray(before, np.int64)[inv.reshape(-1)]
        for row, bch, bn in zip(boots.tolist(), boot_ch.tolist(), boot_node.tolist(), strict=True):
            life[(ch == bch) & (node == bn) & (rows > row)] += 1
        keys, texts = _data_keys(recs, at)
        codes = _codes(keys, texts)
        new = np.ones(len(at), bool)
        if (
            pair.size
            and int(pair.max()) < 1 << 16
            and int(life.max()) < 1 << 20
            and int(index.max()) < 1 << 16
            and int(sub.max()) < 1 << 8
        ):
            # one int64 key in the lexsort's order (bus and node, life, index, sub-index:
            # 16 + 20 + 16 + 8 bits): one stable sort and one compare
            k = (pair << 44) | (life << 24) | (index << 8) | sub
            order = np.argsort(k, kind="stable")
            ks = k[order]
            new[1:] = ks[1:] != ks[:-1]
        else:
            order = np.lexsort((np.arange(len(at)), sub, index, life, node, ch))
            s = [x[order] for x in (ch, node, life, index, sub)]
            new[1:] = np.any([x[1:] != x[:-1] for x in s], axis=0)
        starts = np.flatnonzero(new)
        ends = np.append(starts[1:], len(at))
        code = codes[order]
        differs = np.zeros(len(at), bool)
        differs[1:] = code[1:] != code[:-1]
        t = c.t[at]
        # the changes inside each group (not at its first transfer), found in one pass
        moved = np.flatnonzero(differs & ~new)
        cut = np.searchsorted(moved, starts).tolist() + [moved.size]
        moved = moved.tolist()
        for g, (lo, hi) in enumerate(zip(starts.tolist(), ends.tolist(), strict=True)):
            j0 = int(order[lo])
            key = (labels[ch[j0]], int(node[j0]), int(life[j0]), int(index[j0]), int(sub[j0]))
            changed = moved[cut[g] : cut[g + 1]]
            obj = self.objects.get(key)
            if obj is None:
                shown = _shown(recs.record(int(at[j0])))
                obj = self.objects[key] = _Object(
                    float(t[j0]), _key(keys, texts, j0), history=[shown]
                )
                obj.transfers = 0
            elif _key(keys, texts, j0) != obj.key:
                changed.insert(0, lo)
            obj.transfers += hi - lo
            obj.changes += len(changed)
            room = max(0, HISTORY - 1 - len(obj.history))
            for k in changed[:room]:
                obj.history.append(_shown(recs.record(int(at[order[k]]))))
            obj.more = obj.more or len(changed) > room
            last = int(order[hi - 1])
            obj.key = _key(keys, texts, last)
            obj.rec = recs.record(int(at[last]))
            obj.row = int(rows[last]) + self._off

    def _mapped(self, fb, blocks, labels, boots, boot_ch, boot_node) -> None:
        """The batch's PDO blocks' mapped objects: per life, the last value, the frames
        and the changes, in row order (an object two PDOs carry, or a mapping changed
        within the batch, comes in several blocks)."""
        parts: dict[tuple, list] = {}
        boot_list, boot_ch_list = boots.tolist(), boot_ch.tolist()
        boot_node_list = boot_node.tolist()
        for blk in blocks:
            rows = np.asarray(blk.rows, np.int64)
            ch = int(fb.channel[rows[0]])
            bus, node = labels[ch], int(blk.node)
            before = self.lives.get((bus, node), 0)
            mine = [
                row
                for row, bch, bn in zip(boot_list, boot_ch_list, boot_node_list, strict=True)
                if bch == ch and bn == node
            ]
            if not mine:  # no boot-up of the node in the batch: one life, every row
                for name, (index, sub) in blk.objects.items():
                    got = (rows, np.asarray(blk.columns[name]), name, blk.units)
                    parts.setdefault((bus, node, before, index, sub), []).append(got)
                continue
            life = np.full(rows.size, before, np.int64)
            for row in mine:
                life[rows > row] += 1
            for lv in np.unique(life).tolist():
                sel = life == lv
                for name, (index, sub) in blk.objects.items():
                    got = (rows[sel], np.asarray(blk.columns[name])[sel], name, blk.units)
                    parts.setdefault((bus, node, lv, index, sub), []).append(got)
        for key, got in parts.items():
            if len(got) == 1:  # the usual case: one block, its rows already ascending
                rows, values = got[0][0], got[0][1]
            else:
                rows = np.concatenate([g[0] for g in got])
                values = np.concatenate([g[1] for g in got])
                order = np.argsort(rows, kind="stable")
                rows, values = rows[order], values[order]
            # only the first and last times are read: two lookups, not a gather of every row
            t = (float(fb.t[rows[0]]), float(fb.t[rows[-1]]))
            self._update(key, t, values, got[0][2], got[0][3])
            self.mapped[key].row = int(rows[-1]) + self._off

    def _update(self, key: tuple, t: tuple, values: np.ndarray, name: str, units) -> None:
        """`t`: the first and last row's times."""
        m = self.mapped.get(key)
        if m is None:
            first = _scalar(values[0])
            m = self.mapped[key] = _Mapped(name, t[0], t[0], first, units.get(name))
            m.history.append(scalar_text(first))
        step = values[1:] != values[:-1]
        first = bool(m.frames and _scalar(values[0]) != m.last)
        changes = int(np.count_nonzero(step)) + first
        room = max(0, HISTORY - 1 - len(m.history))
        if room and changes:  # where the history has room: the first changes' values
            shown = ([0] if first else []) + (np.flatnonzero(step)[:room] + 1).tolist()
            m.history += [scalar_text(_scalar(values[k])) for k in shown[:room]]
        m.more = m.more or changes > room
        m.changes += changes
        m.frames += int(values.size)
        m.last, m.t = _scalar(values[-1]), t[1]

    def boot_times(self, bus: str | None, node: int) -> list[float]:
        """The node's boot-up times (`bus` None: a log of one bus, whatever its channel)."""
        if bus is not None:
            return self.boot_t.get((bus, node), [])
        return sorted(t for (_, n), ts in self.boot_t.items() if n == node for t in ts)

    def rows(self) -> list[dict]:
        """One dict per object and life (`OD_COLUMNS`, then `bus` on a log of several
        buses), by bus, node, life, index and sub-index."""
        out = []
        keys = set(self.objects) | set(self.mapped)
        for key in sorted(keys, key=lambda k: (str(k[0]), *k[1:])):
            bus, node, life, index, sub = key
            o = self.objects.get(key)
            m = self.mapped.get(key)
            if o is None or (m is not None and m.row > o.row):
                out.append(self._mapped_row(key))  # the later of an SDO's and a PDO's
                continue
            r = o.rec or {}
            row = {
                "node": node,
                "index": index,
                "subindex": sub,
                "life": life,
                "name": r.get("name"),
                "value": _text(r.get("value")),
                "data": r.get("data"),
                "size": r.get("size"),
                "words": r.get("words") or None,
                "t": r.get("t"),
                "set_by": "write" if r.get("direction") == "download" else "read",
                "t_first": o.t_first,
                "transfers": o.transfers,
                "changes": o.changes,
                "history": _history(o),
            }
            if self.several:
                row["bus"] = bus
            out.append(row)
        return out

    def _mapped_row(self, key: tuple) -> dict:
        """A PDO-mapped object's row: no bytes (the frame's are the PDO's), the value in
        the mapping's unit as words."""
        bus, node, life, index, sub = key
        m = self.mapped[key]
        value = scalar_text(m.last)
        vals = list(m.history) + (["...", value] if m.more else [])
        row = {
            "node": node,
            "index": index,
            "subindex": sub,
            "life": life,
            "name": m.name,
            "value": value,
            "data": None,
            "size": None,
            "words": f"{value} {m.unit}" if m.unit else None,
            "t": m.t,
            "set_by": "pdo",
            "t_first": m.t_first,
            "transfers": m.frames,
            "changes": m.changes,
            "history": " -> ".join(vals),
        }
        if self.several:
            row["bus"] = bus
        return row


def _scalar(v):
    """A numpy value as a Python one."""
    return v.item() if hasattr(v, "item") else v


def _text(value) -> str | None:
    """A value as the text outputs print it (ints in decimal, bytes in hex)."""
    if value is None:
        return None
    if isinstance(value, bytes | bytearray):
        return value.hex()
    if isinstance(value, float) and value.is_integer():
        return repr(value)
    return str(value)


def _shown(rec: dict) -> str:
    """A transfer's value as the history shows it: its bytes (0x...) when it has no
    value of a known type."""
    text = _text(rec.get("value"))
    if text is None:
        data = rec.get("data")
        return f"0x{data}" if data else "-"
    return text


def _history(o: _Object) -> str:
    """The values an object went through, oldest first ("0 -> 100 -> 250"); "..." where
    more changes came than are kept, then the last."""
    vals = list(o.history)
    if o.more:
        vals += ["...", _shown(o.rec or {})]
    return " -> ".join(vals)


def _codes(keys: np.ndarray, texts: dict[int, str]) -> np.ndarray:
    """The data keys as int64 codes that are equal where the keys are (texts coded apart)."""
    if not texts:
        return keys
    out = keys.copy()
    coded: dict[str, int] = {}
    for j, k in texts.items():  # in the transfers' order, as the codes were always given
        out[j] = -1 - coded.setdefault(k, len(coded))
    return out


def _data_keys(recs, at: np.ndarray) -> tuple[np.ndarray, dict[int, str]]:
    """The bytes of each of these transfers as one comparable value, from the records'
    columns (the held ones' dicts): up to 4 bytes (every expedited value) as an int of the
    bytes and their count, longer ones as their hex text. As columns: the ints (int64),
    and the texts by position in `at` (`_key` reads one back)."""
    f = recs.fields()
    a = f.arrays
    n = a["data_len"][at].astype(np.int64)
    raw = np.zeros((len(n), 4), np.uint8)
    raw[:, : min(4, a["raw"].shape[1])] = a["raw"][at, :4]
    raw[np.arange(4) >= n[:, None]] = 0
    # the 4 bytes as one little-endian int (byte j times 256**j), by a view of them
    keys = raw.view("<u4").reshape(-1).astype(np.int64) | (n << 32)
    texts: dict[int, str] = {}
    if f.held:
        held = np.array(sorted(f.held), np.int64)
        pos = np.searchsorted(at, held)  # (at ascends: the held ones among them, in order)
        mine = pos < at.size
        mine[mine] = at[pos[mine]] == held[mine]
        for j, k in zip(pos[mine].tolist(), held[mine].tolist(), strict=True):
            data = f.held[k].get("data") or ""
            raw_bytes = bytes.fromhex(data)
            if len(raw_bytes) <= 4:
                keys[j] = int.from_bytes(raw_bytes, "little") | (len(raw_bytes) << 32)
            else:
                texts[j] = data
    return keys, texts


def _key(keys: np.ndarray, texts: dict[int, str], j: int):
    """One transfer's data key (`_data_keys`) as a Python value."""
    got = texts.get(j)
    return int(keys[j]) if got is None else got
