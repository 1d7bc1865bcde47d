"""Drive 1 on can0 and drive 1 on can1 are two drives, as node 5 on two buses is two
devices (test_several_buses.py): `load().drive_states` and the report's drive lanes
keep each bus's own.

Every test here fails when the outputs merge the buses (the state of one drive drawn
on the other's lane)."""

from __future__ import annotations

import collections
from pathlib import Path

from cananalyze import load
from cananalyze.cli.main import main

DEVICE = {1: "cia402"}
# statuswords on TPDO1 (0x181): can0's drive is enabled step by step, can1's faults
CAN0 = ("switch on disabled", "ready to switch on", "switched on", "operation enabled")
CAN1 = ("switch on disabled", "fault")


def _log(tmp_path: Path) -> Path:
    """Both buses start at 1.0 s: heartbeats of node 1 (operational on can0; pre-operational,
    then stopped on can1), and its statusword every 0.25 s."""
    lines = []
    for k in range(30):
        lines.append((1.0 + 0.1 * k, "can0", "701#05"))
        lines.append((1.0 + 0.1 * k, "can1", "701#7F" if k < 15 else "701#04"))
    for k, w in enumerate((0x40, 0x21, 0x23, 0x27)):
        lines.append((1.01 + 0.25 * k, "can0", f"181#{w:02X}02"))
    for k, w in enumerate((0x40, 0x08)):
        lines.append((1.02 + 0.25 * k, "can1", f"181#{w:02X}02"))
    path = tmp_path / "drives.log"
    path.write_text("".join(f"({t:.6f}) {ch} {f}\n" for t, ch, f in sorted(lines)))
    return path


def test_drive_tables_say_which_bus(tmp_path):
    cap = load(str(_log(tmp_path)), device=DEVICE)
    states = cap.drive_states
    assert list(states.columns)[-1] == "bus"
    by_bus = states.groupby("bus").state.apply(tuple).to_dict()
    assert by_bus == {"can0": CAN0, "can1": CAN1}
    # the drive_state events of each bus agree with the table
    ev = cap.events[cap.events.kind == "drive_state"]
    assert ev.groupby("bus").size().to_dict() == {"can0": len(CAN0), "can1": len(CAN1)}


def test_one_bus_drive_table_has_no_bus_column(tmp_path):
    log = tmp_path / "one.log"
    log.write_text(
        "".join(f"({1 + k * 0.1:.6f}) can0 181#{w:02X}02\n" for k, w in enumerate((0x40, 0x21)))
    )
    assert "bus" not in load(str(log), device=DEVICE).drive_states.columns


def test_report_draws_a_drive_lane_per_bus(tmp_path):
    from tests.outputs.test_report import page_figures

    page = tmp_path / "r.html"
    main(["report", str(_log(tmp_path)), "--device", "1=cia402", "-o", str(page), "-q"])
    figs = page_figures(page.read_text())
    (fig,) = [f for f in figs.values() if f["layout"]["title"]["text"] == "Drive state per node"]
    lanes = collections.defaultdict(set)
    for trace in fig["data"]:
        for lane in trace["y"]:
            lanes[lane].add(trace["name"])
    assert dict(lanes) == {"can0 node 1": set(CAN0), "can1 node 1": set(CAN1)}
