"""DbcDecoder: frames whose identifier a DBC names become signal columns, like PDOs.

Runs after the PDO decoder, which leaves the COB-IDs of the DBC alone: a user's DBC
describes a PDO's layout (scaling, units, value tables) better than the profile, and
names non-CANopen identifiers on a mixed bus. One lookup table per batch gives each row
its message, one stable sort groups the rows, each group is decoded at once
(`dbc.decode_columns`).
"""

from __future__ import annotations

import numpy as np

from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_RTR
from cananalyze.core.records import DecodedBatch, SignalBlock
from cananalyze.devices.dbc import DbcMessage, DbcSet, decode_columns, decode_rows
from cananalyze.protocol.services import Service


class DbcDecoder:
    """Processor: decodes every frame a DBC message describes into a SignalBlock."""

    def __init__(self, dbc: DbcSet) -> None:
        self.dbc = dbc
        self.order = list(dbc.messages.values())
        self.std = np.full(2048, -1, np.int32)  # standard identifier -> message
        ext = sorted((m.frame_id, k) for k, m in enumerate(self.order) if m.extended)
        for k, m in enumerate(self.order):
            if not m.extended and m.frame_id < 2048:
                self.std[m.frame_id] = k
        self.ext_ids = np.array([i for i, _ in ext], np.uint32)
        self.ext_msg = np.array([k for _, k in ext], np.int32)

    def _codes(self, batch: DecodedBatch) -> np.ndarray:
        fb = batch.frames
        code = np.full(len(fb), -1, np.int32)
        usable = (fb.flags & (FLAG_RTR | FLAG_ERR)) == 0
        is_ext = (fb.flags & FLAG_EXT) != 0
        std = usable & ~is_ext & (fb.can_id < 2048)
        code[std] = self.std[fb.can_id[std].astype(np.intp)]
        if self.ext_ids.size:
            ext = np.flatnonzero(usable & is_ext)
            ids = fb.can_id[ext]
            at = np.minimum(np.searchsorted(self.ext_ids, ids), self.ext_ids.size - 1)
            hit = self.ext_ids[at] == ids
            code[ext[hit]] = self.ext_msg[at[hit]]
        return code

    def process(self, batch: DecodedBatch) -> None:
        if not len(batch):
            return
        code = self._codes(batch)
        rows = np.flatnonzero(code >= 0)
        if rows.size == 0:
            return
        order = np.argsort(code[rows], kind="stable")
        keys = code[rows][order]
        cuts = np.flatnonzero(np.diff(keys)) + 1
        starts = np.concatenate(([0], cuts)).tolist()
        ends = np.concatenate((cuts, [keys.size])).tolist()
        for a, b in zip(starts, ends, strict=True):
            self._decode(batch, rows[order[a:b]], self.order[int(keys[a])])

    def _decode(self, batch: DecodedBatch, group: np.ndarray, msg: DbcMessage) -> None:
        fb = batch.frames
        dlc = fb.dlc[group]
        short = dlc < msg.bytes_needed
        if short.any():
            have = ",".join(map(str, sorted(set(dlc[short].tolist()))))
            batch.row_notes.append(
                (
                    group[short],
                    {
                        "pdo_problem": f"DLC {have} shorter than the {msg.bytes_needed} bytes "
                        f"of DBC message {msg.name}: not decoded"
                    },
                )
            )
            group = group[~short]
            if group.size == 0:
                return
        if msg.columnar:
            columns = decode_columns(msg, fb.data[group])
        else:
            columns = decode_rows(msg, [fb.payload(int(r)) for r in group.tolist()])
        first = int(group[0])
        svc = int(batch.service[first])
        if svc in (Service.TPDO, Service.RPDO):
            # the PDO keeps its name, so its series are the same with or without the DBC
            node = int(batch.node[first])
            label = f"{'tpdo' if svc == Service.TPDO else 'rpdo'}{int(batch.pdo[first])}"
        else:
            node, label = -1, msg.name
        batch.signals.append(
            SignalBlock(
                rows=group,
                node=node,
                pdo=label,
                cob_id=int(fb.can_id[first]),
                columns=columns,
                units={s.name: s.unit for s in msg.signals},
                mapped_bytes=msg.bytes_needed,
                choices={s.name: s.choices for s in msg.signals if s.choices},
            )
        )

    def finish(self, batch: DecodedBatch) -> None:
        pass
