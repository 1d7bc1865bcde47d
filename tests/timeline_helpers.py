"""Test helpers: a stand-in PDO processor that fills DecodedBatch.signals from profiles.

The real PDO processor lands from another branch; this one uses the same pieces
(profile default PDOs + decode_pdo) so the exporters are tested on real device maps.
"""

from __future__ import annotations

import argparse

import numpy as np

from cananalyze.capture import Capture, run_pipeline
from cananalyze.cli.pipeline import build_decoder
from cananalyze.decoded import DecodedBatch, SignalBlock
from cananalyze.decoder import Decoder
from cananalyze.network.profile import load_builtin
from cananalyze.protocol.pdo_decode import decode_pdo


class ProfilePdos:
    """SignalBlocks for the default TPDOs of the given {node: profile key}."""

    def __init__(self, devices: dict[int, str]) -> None:
        self.maps = {}
        for node, key in devices.items():
            for cfg in load_builtin(key).pdos(node):
                if cfg.direction == "tx" and cfg.valid and cfg.mapping:
                    self.maps[cfg.cob_id] = (node, f"tpdo{cfg.number}", cfg.mapping)

    def process(self, batch: DecodedBatch) -> None:
        fb = batch.frames
        for cob, (node, name, mapping) in self.maps.items():
            rows = np.flatnonzero(fb.can_id == cob)
            if rows.size == 0:
                continue
            cols = decode_pdo(fb.data[rows], fb.dlc[rows], mapping)
            good = ~cols.short
            batch.signals.append(
                SignalBlock(
                    rows=rows[good],
                    node=node,
                    pdo=name,
                    cob_id=cob,
                    columns={k: v[good] for k, v in cols.values.items()},
                    units={e.name: e.unit for e in mapping},
                )
            )

    def finish(self, batch: DecodedBatch) -> None:
        pass


DEMO_DEVICES = {3: "mcb560", 5: "dat7014"}


def demo_capture(path, devices=None) -> Capture:
    args = argparse.Namespace(log=str(path), strict=False, input_format=None, sdo_timeout=1.0)
    processors = build_decoder(args).processors + [ProfilePdos(devices or DEMO_DEVICES)]
    return run_pipeline(args, decoder=Decoder(processors))
