"""One network schema: the network file and the rules file's `network:` section read alike,
deprecated keys that give the same NetworkSpec, how sources combine, and bad values
reported as one FILE:LINE line."""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import ROOT, SAMPLES

from cananalyze.checks.build import build_checker
from cananalyze.checks.rulesfile import rules_network
from cananalyze.config.netfile import combine, load_network
from cananalyze.core.errors import InputError
from cananalyze.devices.catalog import decoders_dir
from cananalyze.pipeline import Options, network_spec

EDS = decoders_dir() / "dat7014.eds"


def summary(spec) -> dict:
    """What a NetworkSpec says, in comparable form."""
    return {
        "bitrate": spec.bitrate,
        "bus": sorted(spec.bus_writes),
        "known": sorted(spec.known_cob_ids),
        "nodes": {
            n: (
                ns.profile.key if ns.profile else None,
                ns.how,
                ns.writes,
                ns.pdo_lengths,
                ns.sdo_channels,
            )
            for n, ns in sorted(spec.nodes.items())
        },
    }


def write(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(text)
    return path


# --- deprecated keys --------------------------------------------------------------------
ALIASES = [
    ("5: {profile: dat7014}", "5: {device: dat7014}", "profile", 3),
    (f"5: {{profile: {EDS}}}", f"5: {{eds: {EDS}}}", "profile", 3),
    ("5: {emcy_inhibit_100us: 100}", "5: {emcy_inhibit_time: 100}", "emcy_inhibit_100us", 3),
    (
        "5: {tpdo: {2: {inhibit_100us: 50}}}",
        "5: {tpdo: {2: {inhibit_time: 50}}}",
        "inhibit_100us",
        3,
    ),
    (
        "5: {tpdo: {2: {event_timer_ms: 100}}}",
        "5: {tpdo: {2: {event_timer: 100}}}",
        "event_timer_ms",
        3,
    ),
]


@pytest.mark.parametrize("old, new, key, line", ALIASES)
def test_each_deprecated_key_gives_the_same_spec_with_one_warning(
    tmp_path, capsys, old, new, key, line
):
    old_file = write(tmp_path, "old.yaml", f"nodes:\n  {old}\n")
    new_file = write(tmp_path, "new.yaml", f"nodes:\n  {new}\n")
    assert summary(load_network(old_file)) == summary(load_network(new_file))
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"{old_file}:2: '{key}' is deprecated, use ")
    # the rules file's network: section: the same translation, the line in that file
    rules = write(tmp_path, "r.yaml", f"rules: {{}}\nnetwork:\n  nodes:\n    {old}\n")
    assert summary(combine(rules_network(rules))) == summary(
        combine(rules_network(write(tmp_path, "r2.yaml", f"network:\n  nodes:\n    {new}\n")))
    )
    assert capsys.readouterr().err.startswith(f"{rules}:{line + 1}: '{key}' is deprecated")


def test_global_pdos_table_becomes_the_nodes_pdo_tables(tmp_path, capsys):
    old = write(
        tmp_path,
        "old.yaml",
        "nodes:\n  5: {device: dat7014}\n"
        "pdos:\n"
        "  0x285: {node: 5, transmission_type: 5, length: 4}\n"  # TPDO2, predefined
        "  0x205: {node: 5, direction: rx}\n"  # RPDO1
        "  0x1A5: {node: 5, direction: tx, number: 6, inhibit_100us: 10, event_timer_ms: 20}\n"
        "  0x183: {node: 3, inhibit_100us: 1000}\n",  # a node only named here
    )
    new = write(
        tmp_path,
        "new.toml",
        '[nodes.5]\ndevice = "dat7014"\n'
        "[nodes.5.tpdo.2]\ncob_id = 0x285\ntransmission_type = 5\nlength = 4\n"
        "[nodes.5.rpdo.1]\ncob_id = 0x205\n"
        "[nodes.5.tpdo.6]\ncob_id = 0x1A5\ninhibit_time = 10\nevent_timer = 20\n"
        "[nodes.3.tpdo.1]\ncob_id = 0x183\ninhibit_time = 1000\n",
    )
    assert summary(load_network(old)) == summary(load_network(new))
    err = capsys.readouterr().err.splitlines()
    # one warning per deprecated key, each at the line where it is first used
    assert err == [
        f"{old}:3: 'pdos' is deprecated, use the node's tpdo/rpdo tables (nodes.N.tpdo.M)",
        f"{old}:6: 'inhibit_100us' is deprecated, use 'inhibit_time'",
        f"{old}:6: 'event_timer_ms' is deprecated, use 'event_timer'",
    ]


def test_one_warning_per_key_and_file(tmp_path, capsys):
    text = "nodes:\n  3: {profile: mcb560}\n  5: {profile: dat7014}\n"
    first, second = write(tmp_path, "a.yaml", text), write(tmp_path, "b.yaml", text)
    for path in (first, second, first):
        load_network(path)
    err = capsys.readouterr().err.splitlines()
    assert [e.split(":")[0] for e in err] == [str(first), str(second)]


def test_old_and_new_key_together_is_an_error(tmp_path):
    bad = write(tmp_path, "n.yaml", "nodes:\n  5:\n    inhibit: 1\n")
    with pytest.raises(InputError, match=r"n\.yaml:3: nodes\.5\.inhibit: unknown node setting"):
        load_network(bad)
    bad.write_text("nodes:\n  5: {tpdo: {1: {inhibit_time: 1, inhibit_100us: 2}}}\n")
    with pytest.raises(InputError, match="give inhibit_time or the deprecated inhibit_100us"):
        load_network(bad)
    bad.write_text("pdos:\n  0x3A5: {node: 5}\n")
    with pytest.raises(InputError, match=r"n\.yaml:2: pdos\.0x3A5: give number:"):
        load_network(bad)


def test_new_keys_are_object_values(tmp_path):
    net = write(
        tmp_path,
        "n.toml",
        "bitrate = 500000\nknown_cob_ids = [0x10A, '0x7F0']\n"
        "[sync]\nperiod_us = 10000\nwindow_us = 5000\n"
        "[nodes.5]\nheartbeat_ms = 100\nheartbeat_consumer = { 4 = 300, 3 = 250 }\n"
        "guard_time_ms = 100\nlife_time_factor = 3\nemcy_inhibit_time = 20\n"
        "[nodes.5.tpdo.5]\ncob_id = 0x1A5\nenabled = false\nlength = 3\n",
    )
    spec = load_network(net)
    assert spec.bitrate == 500000 and spec.known_cob_ids == {0x10A, 0x7F0}
    assert spec.bus_writes == [(0x1006, 0, 10000), (0x1007, 0, 5000)]
    ns = spec.nodes[5]
    assert ns.writes == [
        (0x1017, 0, 100),
        (0x100C, 0, 100),
        (0x100D, 0, 3),
        (0x1015, 0, 20),
        (0x1016, 1, 3 << 16 | 250),
        (0x1016, 2, 4 << 16 | 300),
        (0x1804, 1, 0x800001A5),
    ]
    assert ns.pdo_lengths == {("tx", 5): 3}


# --- combining sources --------------------------------------------------------------------
def test_rules_network_lies_over_the_network_file_key_by_key_then_the_command_line(tmp_path):
    net = write(
        tmp_path,
        "net.toml",
        '[nodes.5]\ndevice = "dat7014"\nheartbeat_ms = 100\nguard_time_ms = 50\n'
        "heartbeat_consumer = { 3 = 250 }\n"
        "[nodes.5.tpdo.2]\ncob_id = 0x285\nevent_timer = 100\n"
        '[nodes.6]\ndevice = "dat7130"\n',
    )
    rules = write(
        tmp_path,
        "rules.yaml",
        "network:\n  nodes:\n"
        "    5: {heartbeat_ms: 200, heartbeat_consumer: {4: 300}, tpdo: {2: {inhibit_time: 5}}}\n"
        f"    6: {{eds: {EDS}}}\n"
        "  sync: {period_us: 20000}\n",
    )
    spec = network_spec(Options(network=net, rules=rules))
    five, six = spec.nodes[5], spec.nodes[6]
    assert five.profile.key == "dat7014" and five.how == "network file"
    assert dict(((i, s), v) for i, s, v in five.writes) == {
        (0x1017, 0): 200,  # the rules file wins
        (0x100C, 0): 50,  # only the network file says
        (0x1016, 1): 3 << 16 | 250,  # tables merge: both consumer entries
        (0x1016, 2): 4 << 16 | 300,
        (0x1801, 1): 0x285,
        (0x1801, 3): 5,
        (0x1801, 5): 100,
    }
    assert six.profile.source == str(EDS) and six.how == "rules file"  # eds replaces device
    assert spec.bus_writes == [(0x1006, 0, 20000)]
    spec = network_spec(Options(network=net, rules=rules, devices={6: "dat7014"}))
    assert spec.nodes[6].profile.key == "dat7014" and spec.nodes[6].how == "user --device"


def test_rules_network_device_decodes_signals_in_load_and_check(tmp_path, capsys):
    """The faults sample's ch3 of node 5 reads 3276.7: only decoded if node 5's device is
    known, here from the rules file alone (no --network)."""
    import cananalyze
    from cananalyze.cli.main import main

    rules = write(
        tmp_path,
        "rules.yaml",
        "assert:\n  - signal: {node: 5, signal: ch3, min: -200, max: 850}\n"
        "network:\n  nodes:\n    5: {device: dat7014}\n",
    )
    cap = cananalyze.load(SAMPLES / "faults.log", rules=rules)
    ch3 = cap.signals[(cap.signals.node == 5) & (cap.signals.signal == "ch3")]
    assert len(ch3) > 0 and ch3.value.max() == pytest.approx(3276.7)
    assert cap.profiles[5] == ("dat7014", "rules file")
    found = cap.findings[cap.findings.rule == "assert_signal"]
    assert len(found) == 3 and set(found.measured) == {3276.7}
    rc = main(["check", str(SAMPLES / "faults.log"), "--rules", str(rules)])
    out = capsys.readouterr().out
    assert rc == 1 and out.count("assert_signal: ch3 = 3276.7 outside -200..850") == 3
    assert "never seen" not in out


# --- bad values ---------------------------------------------------------------------------
BAD = [
    ("n.yaml", "nodes:\n  5: {heartbeat_ms: true}\n", r":2: nodes\.5\.heartbeat_ms: expected an integer, got True"),
    ("n.yaml", "nodes:\n  5: {guard_time_ms: -5}\n", r":2: nodes\.5\.guard_time_ms: -5 is out of range"),
    ("n.yaml", "nodes:\n  5:\n    life_time_factor: often\n", r":3: .*expected an integer, got 'often'"),
    ("n.yaml", "nodes:\n  200: {heartbeat_ms: 100}\n", r":2: nodes\.200: 200 is out of range 1\.\.127"),
    ("n.yaml", "nodes: [1, 2]\n", r":1: nodes: expected a table keyed by node-ID, got a list"),
    ("n.yaml", "nodes:\n  5: {heartbeat_consumer: [3, 250]}\n", r":2: .*heartbeat_consumer: expected a table"),
    ("n.yaml", "nodes:\n  5: {heartbeat_consumer: {3: 2.5}}\n", r":2: .*heartbeat_consumer\.3: expected an integer"),
    ("n.yaml", "nodes:\n  5:\n    tpdo:\n      1: [1]\n", r":4: nodes\.5\.tpdo\.1: expected a table of PDO"),
    ("n.yaml", "nodes:\n  5:\n    tpdo:\n      2: {length: 9}\n", r":4: .*length: 9 is out of range 0\.\.8"),
    ("n.yaml", "nodes:\n  5:\n    tpdo:\n      5: {enabled: false}\n", r":4: nodes\.5\.tpdo\.5: tpdo5 needs a cob_id"),
    ("n.yaml", "known_cob_ids: 0x10A\n", r":1: known_cob_ids: expected a list"),
    ("n.yaml", "sync: {period_us: -5}\n", r":1: sync\.period_us: -5 is out of range"),
    ("n.yaml", "sync: {period: 5}\n", r":1: sync\.period: unknown sync setting"),
    ("n.yaml", "pdos:\n  0x285: {transmission_type: 5}\n", r":2: pdos\.0x285: each PDO here needs at least node"),
    ("n.yaml", "pdos:\n  0x285: {node: 5, direction: out}\n", r":2: pdos\.0x285\.direction: direction is tx or rx"),
    ("n.yaml", "pdos:\n  0x285:\n    node: 5\n    inhibit_100us: x\n", r":4: nodes\.5\.tpdo\.2\.inhibit_time: expected an integer, got 'x'"),
    ("n.toml", "[nodes.5]\nguard_time_ms = 1.5\n", r":2: nodes\.5\.guard_time_ms: expected an integer, got 1\.5"),
    ("n.toml", '[nodes.5]\nheartbeat_ms = "100 ms"\n', r":2: .*expected an integer, got '100 ms'"),
    ("r.yaml", "network:\n  nodes: [1, 2]\n", r":2: network\.nodes: expected a table keyed by node-ID"),
    ("r.yaml", "network:\n  nodes:\n    5: {heartbeat_ms: false}\n", r":3: network\.nodes\.5\.heartbeat_ms: expected an integer, got False"),
    ("r.yaml", "network:\n  bitrate: fast\n", r":2: network\.bitrate: expected an integer"),
    ("r.yaml", "network: [1]\n", r":1: network: a network description is a table"),
    ("r.yaml", "network:\n  nodes:\n    5: {profile: nosuch}\n", r":3: network\.nodes\.5\.eds: no such EDS/DCF file"),
]  # fmt: skip


@pytest.mark.parametrize("name, text, message", BAD)
def test_bad_values_are_one_line_naming_file_and_line(tmp_path, capsys, name, text, message):
    path = write(tmp_path, name, text)
    with pytest.raises(InputError, match=f"^{path}{message}"):
        build_checker(path) if name.startswith("r.") else load_network(path)
    flag = "--rules" if name.startswith("r.") else "--network"
    proc = subprocess.run(
        [sys.executable, "-m", "cananalyze", "check", str(SAMPLES / "demo.log"), flag, str(path)],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    lines = [ln for ln in proc.stderr.splitlines() if "deprecated" not in ln]
    assert proc.returncode == 2 and len(lines) == 1 and "Traceback" not in proc.stderr
    assert lines[0].startswith(f"cananalyze: error: {path}:")
