"""Builds the Decoder with the processors the command-line options ask for."""

from __future__ import annotations

import argparse

from ..decoder import Decoder
from ..errors import UsageError
from ..network.spec import NetworkSpec
from ..sdo.processor import SdoProcessor
from ..sdo.tracker import SdoTracker


def _node_assignments(items: list[str], option: str) -> list[tuple[int, str]]:
    out = []
    for item in items or []:
        node, sep, value = item.partition("=")
        try:
            node_id = int(node, 0)
        except ValueError:
            node_id = -1
        if not sep or not value or not 1 <= node_id <= 127:
            raise UsageError(f"{option} takes NODE=VALUE with NODE 1..127 (got {item!r})")
        out.append((node_id, value))
    return out


def network_spec(args: argparse.Namespace) -> NetworkSpec:
    """The user's declarations: the network file first, then --device/--eds on top."""
    devices = _node_assignments(getattr(args, "device", None), "--device")
    eds = _node_assignments(getattr(args, "eds", None), "--eds")
    path = getattr(args, "network", None)
    if path:
        from ..network.netfile import load_network

        spec = load_network(path)
    else:
        spec = NetworkSpec()
    if devices or eds:
        from ..network.profile import load_builtin, load_eds

        for node, name in devices:
            ns = spec.node(node)
            ns.profile, ns.how = (
                load_builtin(name.lower().replace("-", "").replace(" ", "")),
                "user --device",
            )
        for node, file in eds:
            ns = spec.node(node)
            ns.profile, ns.how = load_eds(file, node), "user --eds"
    return spec


def build_decoder(args: argparse.Namespace) -> Decoder:
    """Processor order matters: SDO transactions first (the network model reads them)."""
    from ..network.emcy_notes import EmcyDecoder
    from ..network.model import NetworkModel
    from ..network.pdo_processor import PdoDecoder

    model = NetworkModel(network_spec(args))
    tracker = SdoTracker(timeout=getattr(args, "sdo_timeout", 1.0), object_info=model.object_info)
    for node, request, response in model.sdo_channels:
        tracker.add_channel(node, request, response)
    processors: list = [SdoProcessor(tracker), model, PdoDecoder(model), EmcyDecoder(model)]
    decoder = Decoder(processors)
    model.attach(decoder)
    decoder.network = model  # for checks and outputs that ask about the configuration
    return decoder
