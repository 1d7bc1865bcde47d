"""`cananalyze simulate`: logs on the simulated clock, real time on a virtual bus, errors."""

from __future__ import annotations

import time

import can
import numpy as np
from conftest import ROOT, SAMPLES

from cananalyze.cli.main import main
from cananalyze.formats.source import read_all
from cananalyze.sim.network import load_network
from cananalyze.sim.session import simulate


def test_to_file_matches_the_library_and_is_deterministic(tmp_path, capsys):
    out = tmp_path / "run.log"
    args = ["simulate", "--to", str(out), "--duration", "3", "--seed", "7", "--scenario", "faults"]
    assert main(args) == 0
    assert "frames" in capsys.readouterr().out
    first = out.read_bytes()
    assert main(args) == 0
    assert out.read_bytes() == first
    batch = read_all(out)
    ref = simulate(scenario="faults", duration=3.0, seed=7)
    assert len(batch) == len(ref) > 100
    assert np.array_equal(batch.can_id, ref.can_id)
    assert np.array_equal(batch.data, ref.data)


def test_to_blf_and_asc(tmp_path):
    for suffix in (".blf", ".asc"):
        out = tmp_path / f"run{suffix}"
        assert main(["simulate", "--to", str(out), "--duration", "1.5"]) == 0
        batch = read_all(out)
        assert sorted(set(batch.can_id[(batch.can_id & 0x780) == 0x700].tolist())) == [
            0x703,
            0x705,
            0x706,
            0x707,
        ]


def test_network_file_with_builtin_and_eds(tmp_path):
    net = tmp_path / "net.toml"
    eds = ROOT / "decoders" / "dat7014.eds"
    net.write_text(
        f'bitrate = 250000\n[nodes.9]\ndevice = "mcb560"\nheartbeat_ms = 50\n'
        f'[nodes.12]\neds = "{eds}"\n'
    )
    sim_net = load_network(net)
    assert sim_net.bitrate == 250000 and sorted(sim_net.profiles) == [9, 12]
    out = tmp_path / "n.log"
    args = ["simulate", "--network", str(net), "--to", str(out), "--duration", "1.2"]
    assert main(args + ["--scenario", "commissioning"]) == 0
    batch = read_all(out)
    assert {0x709, 0x70C} <= set(batch.can_id.tolist())
    # heartbeat_ms of the network file is the node's stored 0x1017: 50 ms from boot-up
    t = batch.t[batch.can_id == 0x709]
    assert np.allclose(np.diff(t[1:4]), 0.05, atol=1e-3)
    assert load_network(SAMPLES / "network.toml").profiles[7].key == "i7231d"


def test_errors_are_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    cases = [
        (["simulate"], "either --to FILE or -i"),
        (["simulate", "--to", str(tmp_path / "a.log"), "-i", "virtual", "-c", "x"], "either"),
        (["simulate", "--to", str(tmp_path / "a.txt")], "writes .log"),
        (["simulate", "--to", str(tmp_path / "a.log"), "--duration", "0"], "positive"),
        (["simulate", "--network", str(tmp_path / "none.toml"), "--to", "x.log"], "cannot read"),
        (["simulate", "--network", str(SAMPLES / "rules.yaml"), "--to", "x.log"], "rules.yaml"),
        (["simulate", "--to", str(tmp_path / "a.log"), "--bus-option", "port=1"], "-i/-c"),
        (["simulate", "-i", "virtual", "-c", "x", "--bus-option", "port"], "KEY=VALUE"),
    ]
    for args, text in cases:
        assert main(args) == 2
        err = capsys.readouterr().err
        assert text in err and err.count("\n") == 1
    for content, text in [
        ("[nodes.3]\ndevice = 'nope'\n", "unknown device"),
        ("[nodes.300]\ndevice = 'mcb560'\n", "300"),
        ("[nodes.3]\nheartbeat_ms = 100\n", "needs its device or eds"),
        ("nodes = [\n", ""),
        ("bitrate = 5\n", "no nodes"),
    ]:
        bad.write_text(content)
        assert main(["simulate", "--network", str(bad), "--to", str(tmp_path / "b.log")]) == 2
        err = capsys.readouterr().err
        assert text in err and str(bad) in err and err.count("\n") == 1


def test_real_time_on_a_virtual_bus():
    channel = f"cli-{time.monotonic_ns()}"
    listener = can.Bus(interface="virtual", channel=channel)
    try:
        assert main(["simulate", "-i", "virtual", "-c", channel, "--duration", "1.2"]) == 0
        seen = []
        while (msg := listener.recv(timeout=0)) is not None:
            seen.append(msg)
    finally:
        listener.shutdown()
    ids = [m.arbitration_id for m in seen]
    assert sorted(
        i for i, m in zip(ids, seen, strict=True) if i >= 0x700 and m.data == b"\x00"
    ) == [
        0x703,
        0x705,
        0x706,
        0x707,
    ]  # boot-ups
    assert 0x000 in ids and 0x080 in ids  # NMT start and SYNC from the master
    assert any(0x580 < i < 0x600 for i in ids)  # SDO answers to the heartbeat configuration
    hb = [m.timestamp for m in seen if m.arbitration_id == 0x705 and m.data == b"\x05"]
    assert len(hb) >= 3 and 0.07 < float(np.median(np.diff(hb))) < 0.13
