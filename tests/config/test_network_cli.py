"""decode with --eds/--device/--network and --signals, end to end through the CLI."""

from __future__ import annotations

import json

from cananalyze.cli.main import main
from tests.conftest import real_file


def test_decode_signals_jsonl_with_eds(tmp_path, capsys):
    eds = real_file("jclinton830__canopen_test/roboteq_motor_controllers_v80.eds")
    log = real_file("jclinton830__canopen_test/candump.txt")
    assert main(["decode", str(log), "--eds", f"12={eds}", "--signals", "--format", "jsonl"]) == 0
    recs = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert recs and all(r["kind"] == "signal" for r in recs)
    hits = [r for r in recs if r["cob_id"] == 0x20C and r["value"] == 1000]
    assert hits and hits[0]["node"] == 12 and hits[0]["pdo"] == "rpdo1"


def test_decode_text_shows_signals_and_bad_option(tmp_path, capsys):
    log = tmp_path / "x.log"
    log.write_text("(1.0) can0 285#E803000000000000\n")
    assert main(["decode", str(log), "--device", "5=dat7014", "--no-color"]) == 0
    assert "ch1=100 °C" in capsys.readouterr().out
    assert main(["decode", str(log), "--device", "x=dat7014"]) == 2
    net = tmp_path / "n.toml"
    net.write_text('[nodes.5]\ndevice = "nope"\n')
    assert main(["decode", str(log), "--network", str(net)]) == 2
    assert "n.toml:2" in capsys.readouterr().err
