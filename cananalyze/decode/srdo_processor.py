"""SrdoDecoder: the normal frame of each SRDO pair becomes named values, like a PDO's.

A pair is decoded once: the normal frame, by the normal objects of the mapping in force
at its time (the network model's SRDO log); the inverted frame carries the same values
bit-inverted, which the `srdo` rule compares, so it gets no signals of its own. The
layout is protocol/srdo.py's; the decoding is the PDO's (`decode_pdo`), one group of
rows per COB-ID and configuration.
"""

from __future__ import annotations

import numpy as np

from cananalyze.core.frames import FLAG_RTR
from cananalyze.core.records import DecodedBatch, SignalBlock
from cananalyze.decode.model import NetworkModel
from cananalyze.protocol.pdo import decode_pdo, words_of
from cananalyze.protocol.services import Service


class SrdoDecoder:
    """Processor after the network model: decodes SRDOs with the mapping in force."""

    def __init__(self, model: NetworkModel, skip: set[int] | frozenset[int] = frozenset()) -> None:
        self.model = model
        self.skip = frozenset(skip)  # a DBC's identifiers: its layout wins

    def process(self, batch: DecodedBatch) -> None:
        if not self.model.srdo_log or len(self.model.srdo_log) == 1 and not self.model.srdo_log[0]:
            return  # no SRDO configured anywhere, ever
        fb = batch.frames
        rows = np.flatnonzero((batch.service == Service.SRDO) & ((fb.flags & FLAG_RTR) == 0))
        if rows.size == 0:
            return
        k = self.model.srdo_log_index(fb.t[rows])
        key = k.astype(np.int64) * 4096 + fb.can_id[rows].astype(np.int64)
        words = None
        for group_key in np.unique(key).tolist():
            log_k, cob = divmod(group_key, 4096)
            if cob in self.skip:
                continue
            found = self.model.srdo_log[log_k].get(cob)
            if found is None or found[1]:
                continue
            config = found[0]
            group = rows[key == group_key]
            if not config.mapping:
                batch.row_notes.append(
                    (
                        group,
                        {
                            "pdo_problem": f"SRDO{config.number} of node {config.node}: "
                            "mapping not known"
                        },
                    )
                )
                continue
            if words is None:
                words = words_of(fb.data)
            dlc = fb.dlc[group]
            cols = decode_pdo(None, dlc, list(config.mapping), words=words[group])
            if cols.short.any():
                have = ",".join(map(str, sorted(set(dlc[cols.short].tolist()))))
                batch.row_notes.append(
                    (
                        group[cols.short],
                        {
                            "pdo_problem": f"DLC {have} shorter than the {cols.bytes_needed} "
                            f"bytes mapped in SRDO{config.number}: not decoded"
                        },
                    )
                )
            ok = ~cols.short
            if not ok.any() or not cols.values:
                continue
            units: dict[str, str | None] = {}
            for e in config.mapping:
                units.setdefault(e.name, e.unit)
            batch.signals.append(
                SignalBlock(
                    rows=group[ok],
                    node=config.node,
                    pdo=config.name,
                    cob_id=cob,
                    columns={name: v[ok] for name, v in cols.values.items()},
                    units={name: units.get(name) for name in cols.values},
                    mapped_bytes=cols.bytes_needed,
                    objects={
                        e.name: (e.index, e.subindex)
                        for e in config.mapping
                        if e.name in cols.values
                    },
                )
            )

    def finish(self, batch: DecodedBatch) -> None:
        pass
