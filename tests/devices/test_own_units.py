"""Your own units: a TOML sidecar beside a user's EDS, and `signals` in the network file
(and the rules file's `network:`), on the real Axiomatic log (raw 3128 = 3.128)."""

from __future__ import annotations

import shutil
import subprocess
import sys

import pytest

import cananalyze
from tests.conftest import real_file

AXIO = "calumroy__CANopen_socketCAN_Test/"
SIDECAR = """
# my units for the brake sensor bench (same format as decoders/*.toml)
notes = ["input 1 is the brake pressure sensor"]

[[signal]]
index = 0x7100
subindex = 1
name = "brake"
unit = "bar"
scale = 0.001

[[signal]]
index = 0x7100
subindex = [2, 3]
name = "aux{sub}"
unit = "V"
scale = 0.01
"""


@pytest.fixture
def eds_with_sidecar(tmp_path):
    eds = tmp_path / "axiomatic.eds"
    shutil.copy(real_file(AXIO + "EDS-23123-1.01.eds"), eds)
    (tmp_path / "axiomatic.toml").write_text(SIDECAR)
    return eds


def _first(cap, name):
    sig = cap.signals
    return sig[sig.signal == name].iloc[0]


def test_sidecar_beside_users_eds(eds_with_sidecar):
    log = real_file(AXIO + "can_log_070825_brake_sensor_test1.log")
    cap = cananalyze.load(log, eds={127: eds_with_sidecar})
    first = _first(cap, "brake")
    assert first.value == pytest.approx(3.128) and first.unit == "bar"
    assert _first(cap, "aux2").unit == "V"
    # the EDS alone (no sidecar): the object's own name, raw
    bare = cananalyze.load(log, eds={127: real_file(AXIO + "EDS-23123-1.01.eds")})
    assert "brake" not in set(bare.signals.signal)
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", "devices", str(eds_with_sidecar), "--node", "127"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert "7100:01 brake [bar] x0.001" in out
    assert "input 1 is the brake pressure sensor" in out


def test_network_file_sets_unit_and_scale(tmp_path, eds_with_sidecar):
    log = real_file(AXIO + "can_log_070825_brake_sensor_test1.log")
    net = tmp_path / "net.toml"
    net.write_text(
        f'[nodes.127]\neds = "{eds_with_sidecar}"\n'
        '[nodes.127.signals]\n"7100:01" = { unit = "kPa", scale = 0.1 }\n'
        '"7100:04" = { name = "pedal", unit = "%", scale = 0.5, offset = -10 }\n'
    )
    cap = cananalyze.load(log, network=net)
    first = _first(cap, "brake")  # the sidecar's name, the network file's unit and scale
    assert first.value == pytest.approx(312.8) and first.unit == "kPa"
    pedal = _first(cap, "pedal")
    assert pedal.value == pytest.approx(2 * 0.5 - 10) and pedal.unit == "%"
    # the same schema in the rules file's network: section (YAML), read by the same code
    rules = tmp_path / "rules.yaml"
    rules.write_text(
        f"network:\n  nodes:\n    127:\n      eds: {eds_with_sidecar}\n"
        "      signals:\n        '7100:01': {unit: mbar, scale: 1}\n"
    )
    cap = cananalyze.load(log, rules=rules)
    first = _first(cap, "brake")
    assert first.value == pytest.approx(3128) and first.unit == "mbar"


@pytest.mark.parametrize(
    "body, message",
    [
        ('"71:01:02" = { unit = "x" }', "signal key '71:01:02' is not an object 'INDEX:SUB'"),
        ('"7100:01" = { scale = "big" }', "expected a number, got 'big'"),
        ('"7100:01" = { colour = "red" }', "unknown signal setting"),
    ],
)
def test_bad_signal_settings_name_the_line(tmp_path, body, message):
    net = tmp_path / "net.toml"
    net.write_text(f"[nodes.5]\n[nodes.5.signals]\n{body}\n")
    log = tmp_path / "bus.log"
    log.write_text("(0.0) can0 185#00\n")
    r = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(log), "--network", str(net)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2
    assert f"{net}:3:" in r.stderr and message in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
