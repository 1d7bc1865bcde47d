"""The report's sections, in reading order, as plain data for the page's templates.

Each takes the ReportSink's summaries and a `Figures` that collects the plots, and
returns what its section shows (None: no section), as text and numbers, unescaped:
the macro of the same name in `templates.py` lays it out and escapes it. Nothing here
judges the log: the verdict and every alarm are the Checker's findings, the tables
show what was measured beside what was configured.
"""

from __future__ import annotations

import hashlib
import math
import re
from collections import defaultdict
from typing import NamedTuple

from cananalyze.checks.model_config import ModelConfig
from cananalyze.core.finding import show
from cananalyze.outputs.junit import format_finding
from cananalyze.outputs.report import plots


class Plot(NamedTuple):
    """A plot's placeholder: the element the page's loader draws figure `id` in."""

    id: str
    cls: str


class Figures:
    """Plot placeholders and their figures (`plots`), drawn by the page's loader."""

    def __init__(self) -> None:
        self.items: list[tuple[str, dict]] = []

    def add(self, fig: dict, cls: str = "plot") -> Plot:
        pid = f"fig{len(self.items)}"
        self.items.append((pid, fig))
        return Plot(pid, cls)


def _ms(v: float | None, nd: int = 2) -> str:
    if v is None or v != v or v in (float("inf"), float("-inf")):
        return "-"
    return f"{v:.{nd}f}"


def _rel(s, t: float | None) -> str:
    return "-" if t is None else f"{t - s.t0:+.3f} s"


def verdict(s, figs: Figures) -> dict:
    failing = [f for f in s.findings if f.fails]
    rules = s.rules
    counts: dict[str, int] = {}
    for r in rules:  # a rules file's assertions share a name: one entry each, counted
        counts[r.name] = counts.get(r.name, 0) + 1
    names = ", ".join(f"{n} ×{k}" if k > 1 else n for n, k in counts.items())
    dur = (s.t_last - s.t_first) if s.t_first is not None else 0.0
    over = f"over {dur:.1f} s" if s.timed else "(the log has no timestamps)"
    text = (
        f"{len(rules)} rules: {len(failing)} violation(s), {len(s.findings) - len(failing)} "
        f"note(s) in {s.frames:,} frames {over}"
    )
    # a log without times has no load over time (every frame at one instant)
    load = figs.add(plots.bus_load(s.buses, s.t0, s.bitrate)) if s.buses and s.timed else None
    return {
        "ok": not failing,
        "text": text,
        "rules": names,
        "skipped": s.run.problems.count,
        "load": load,
    }


def buses(s, figs: Figures) -> dict:
    rows = []
    for ch, b in s.buses.items():
        unit = 100.0 / s.bitrate if s.bitrate else 1e-3
        u = "%" if s.bitrate else " kbit/s"
        rows.append(
            [
                ch,
                f"{b.frames:,}",
                f"{b.errors:,}",
                # a log without times has no load (its frames share one instant)
                f"{b.load.mean * unit:.2f}{u}" if s.timed else "-",
                f"{b.load.peak * unit:.2f}{u}" if s.timed else "-",
            ]
        )
    nodes = []  # each node's share (node_load: the frames it sent, as the summary's)
    load = s.tally.load  # the nodes table's figures
    shares = load.shares(s.bitrate) if s.timed else {}
    for ch, (frames, _) in load.sent.items():
        for n, share in shares.get(ch, {}).items():
            nodes.append([s.who(ch, n), f"{int(frames[n]):,}", f"{share:.2f}%"])
    bursts = [  # the decoder's longest burst per bus (with a bitrate and times)
        [
            ch,
            f"{rec['frames']:,}",
            f"{rec['t_start'] - s.t0:+.6f} s",
            f"{(rec['t_end'] - rec['t_start']) * 1000:.3f} ms",
        ]
        for ch, rec in load.bursts.items()
        if s.timed
    ]
    return {"rows": rows, "bitrate": s.bitrate, "nodes": nodes, "bursts": bursts}


# findings listed per node and rule: all are counted, `check --json`/JUnit hold every one.
# 50 lines say what a group is; at 200 the list was 1.8 of a 10M-frame page's 5.4 MB
LISTED = 50


def _without_why(f) -> str:
    """A finding's line (`format_finding`, as JUnit and check print it) without its
    explanation, which the group shows once."""
    text = format_finding(f)
    return text[: -len(f.why)].rstrip() if f.why and text.endswith(f.why) else text


def findings(s, figs: Figures) -> dict:
    groups: dict[tuple, list] = defaultdict(list)
    for f in s.findings:
        groups[(f.bus or "", f.node is None, f.node or 0, f.rule)].append(f)
    out = []
    for (bus, _, node, rule), fs in sorted(groups.items()):
        who = "bus" if fs[0].node is None else f"node {node}"
        who = f"{bus} {who}" if bus else who  # several buses: "can1 node 5"
        sev = "error" if any(f.fails for f in fs) else fs[0].severity
        first = fs[0]
        shown = fs[:LISTED]
        out.append(
            {
                "severity": sev,
                "who": who,
                "rule": rule,
                "count": len(fs),
                "first_at": _rel(s, first.t),
                "message": first.message,
                "measured": show(first.measured),
                "expected": show(first.expected),
                # each explanation once, above the list: repeated on every line it made
                # most of a 10M-frame page (3.4 of 7 MB for 16 nodes' 86k SYNC and EMCY
                # findings)
                "whys": list(dict.fromkeys(f.why for f in shown)),
                "lines": [_without_why(f) for f in shown],
                "more": max(len(fs) - LISTED, 0),  # listed as a count
            }
        )
    return {"groups": out}


def differences(s, figs: Figures) -> dict | None:
    """`report --against B`: what `diff LOG B` names, a row each; with --node, those
    nodes' (and the network's) only."""
    c = s.differences
    if c is None:
        return None
    nodes = s.run.options.nodes
    found = [
        d
        for d in c.differences
        if nodes is None or d.node == "network" or int(d.node.rpartition("/")[2]) in nodes
    ]
    return {
        "reference": c.reference,
        "kind": c.kind,
        "rows": [list(d.cells) for d in found],
        "note": c.note,
    }


def _node_name(n: int, bus: str | None) -> str:
    return f"Node {n}" if bus is None else f"{bus} node {n}"


def _node_id(n: int, bus: str | None) -> str:
    """The node's element id ("node-5", "node-can1-5"): a bus's name as it is where it
    is a slug, else its other characters as "-" and a hash of the name (unique)."""
    if bus is None:
        return f"node-{n}"
    slug = re.sub(r"[^A-Za-z0-9_-]", "-", bus)
    if slug != bus:
        slug += "-" + hashlib.sha1(bus.encode()).hexdigest()[:8]
    return f"node-{slug}-{n}"


def nodes(s, figs: Figures) -> dict:
    from cananalyze.decode.node_tally import bus_profiles, node_profiles

    model = s.run.network
    rows = s.tally.rows(
        node_profiles(model) if model is not None else {}, bus_profiles(s.run.decoder)
    )
    configs = _Configs(s)
    timeline = None
    if s.states:
        lanes = [(t, s.who(bus, n), state) for t, (bus, n), state in s.states]
        x0, x_end, x = s.axis()
        timeline = figs.add(plots.state_timeline(lanes, x0, x_end, x=x))
    out = []
    for row in rows:
        n = row["node"]
        bus = row.get("bus")  # several buses: one section per bus and node
        dev = row.get("profile") or "unknown device"
        how = row.get("identified_by") or "not identified"
        ident = ", ".join(
            f"{k} {v:#x}" if isinstance(v, int) else f"{k} {v}"
            for k in ("vendor_id", "product_code", "revision", "serial", "device_name")
            if (v := row.get(k)) is not None
        )
        periods = []
        cfg = configs[bus]  # that bus's configuration, as its checker judged
        for kind in ("heartbeat", "guarding"):
            g = s.errctl.get((kind, n) if bus is None else (kind, n, bus))
            if g is None or g.hist.n == 0 or not s.timed:  # no times: no periods
                continue
            conf = _configured(cfg, kind, n, g) if cfg is not None else []
            h = g.hist
            st = h.stats()  # the numbers `--summary` prints, from the same computation
            who = _node_name(n, bus)
            marks = sorted({v for _, v in conf})
            periods.append(
                {
                    "kind": kind,
                    "count": f"{h.n:,}",
                    "min": _ms(st["min"]),
                    "median": _ms(st["median"]),
                    "mean": _ms(st["mean"]),
                    "p99": _ms(st["p99"]),
                    "max": _ms(st["max"]),
                    "std": _ms(st["jitter"]),
                    "configured": (
                        "configured " + ", ".join(sorted({_ms(v, 0) for _, v in conf})) + " ms"
                        if conf
                        else "not configured"  # not "configured not configured ms"
                    ),
                    "plot": figs.add(plots.period(g, s.t0, kind, who, conf), "plot half"),
                    "histogram": figs.add(
                        plots.histogram(h, f"{who} {kind} period histogram", "period (ms)", marks),
                        "plot half",
                    ),
                }
            )
        out.append(
            {
                "id": _node_id(n, bus),
                "name": _node_name(n, bus),
                "device": str(dev),
                "how": str(how),
                "ident": ident,
                "frames": f"{row['frames']:,}",
                "last_state": str(row.get("last_state") or "-"),
                "periods": periods,
            }
        )
    return {"timeline": timeline, "states_dropped": s.states_dropped, "nodes": out}


class _Configs(dict):
    """One ModelConfig per bus, made on first use (it caches the changes it looks up)."""

    def __init__(self, sink) -> None:
        super().__init__()
        self.sink = sink

    def __missing__(self, bus: str | None) -> ModelConfig | None:
        model = self.sink.network_of(bus)
        cfg = self[bus] = ModelConfig(model) if model is not None else None
        return cfg


def _configured(cfg: ModelConfig, kind: str, node: int, g) -> list[tuple[float, float]]:
    """(time, configured period ms) where it changes, sampled along the log."""
    out: list[tuple[float, float]] = []
    a, b = g.first_t or 0.0, g.last_t or 0.0
    for k in range(65):
        t = a + (b - a) * k / 64
        if kind == "heartbeat":
            v = cfg.heartbeat_ms(node, t)
        else:
            gv = cfg.guarding(node, t)
            v = None if gv is None else gv[0]
        if v and (not out or out[-1][1] != v):
            out.append((t, v))
    return out


def sdo(s, figs: Figures) -> dict | None:
    if not s.sdo_count:
        return None
    from cananalyze.checks.streamstats import StreamStats

    rows = []
    for (bus, n), (ok, bad, h) in sorted(_sdo_by_bus(s).items()):
        who = s.who(bus, n) if s.several else n
        if h is not None and h.n and s.timed:
            st = h.stats()
            rows.append(
                [
                    who,
                    ok + bad,
                    bad,
                    _ms(st["min"]),
                    _ms(st["median"]),
                    _ms(st["p99"]),
                    _ms(st["max"]),
                ]
            )
        else:
            rows.append([who, ok + bad, bad, "-", "-", "-", "-"])
    allh = StreamStats()
    for h in s.sdo_latency.values():
        allh.merge(h)
    latency = None
    if allh.n and s.timed:  # a log without times has no latencies
        latency = figs.add(plots.histogram(allh, "SDO latency", "latency (ms)"))
    aborts = [
        [
            _rel(s, r.get("t")),
            s.who(s.first_bus(bus), r["node"])
            if s.several and r.get("node") is not None
            else r.get("node"),
            str(r.get("direction") or ""),
            f"0x{r.get('index', 0):04X}:{r.get('subindex', 0):02X}",
            str(r.get("name") or ""),
            _abort_code(r),
            str(r.get("abort_text") or r.get("result") or ""),
        ]
        for bus, r in s.aborts
    ]
    return {"rows": rows, "latency": latency, "aborts": aborts}


def _sdo_by_bus(s) -> dict:
    """(bus, node) -> [ok, aborts, latency histogram]: the transfers counted before a
    second bus was seen (bus "") are the first bus's."""
    from cananalyze.checks.streamstats import StreamStats

    out: dict = {}
    for (bus, n), (ok, bad) in s.sdo_count.items():
        item = out.setdefault((s.first_bus(bus), n), [0, 0, StreamStats()])
        item[0] += ok
        item[1] += bad
        h = s.sdo_latency.get((bus, n))
        if h is not None:
            item[2].merge(h)
    return out


def emcy(s, figs: Figures) -> dict | None:
    """Each EMCY and how long it stayed active, in log order: a log without times orders
    by line and says at which line an error ended instead of after how long."""
    if not s.emcys:
        return None
    timed = s.timed
    active: dict[tuple[str, int], list] = {}  # (bus, node): node 5 on each bus its own
    rows = []
    resets = sorted(s.bootups)
    for t, line, bus, node, code, reg, text in sorted(s.emcys, key=lambda e: e[:2]):
        if code == 0:
            for item in active.pop((bus, node), []):
                item[2] = f"{t - item[0]:.3f} s" if timed else f"reset at line {line}"
            continue
        item = [t, s.who(bus, node), "still active at the end of the log", code, reg, text, line]
        active.setdefault((bus, node), []).append(item)
        rows.append(item)
    for t, line, bus, node in resets:  # a boot-up clears the node's errors
        for item in list(active.get((bus, node), [])):
            if (item[0], item[6]) < (t, line):
                item[2] = (
                    f"{t - item[0]:.3f} s (until boot-up)"
                    if timed
                    else f"until the boot-up at line {line}"
                )
                active[(bus, node)].remove(item)
    out = [
        [
            _rel(s, t) if timed else f"line {line}",
            who.removeprefix("node "),
            f"0x{code:04X}" if code >= 0 else "-",
            f"0x{reg:02X}" if reg >= 0 else "-",
            text,
            dur,
        ]
        for t, who, dur, code, reg, text, line in rows
    ]
    return {"rows": out, "more": s.emcy_count - len(s.emcys)}


def pdos(s, figs: Figures) -> dict | None:
    if not s.pdos:
        return None
    configs = _Configs(s)
    per_cob: dict[tuple[str, int], int] = defaultdict(int)
    for f in s.findings:
        if f.cob_id is not None and f.rule.startswith("pdo"):
            per_cob[(f.bus or "", f.cob_id)] += 1
    rows = []
    for bus, cob in sorted(s.pdos):
        g = s.pdos[(bus, cob)]
        node, name = s.pdo_node.get((bus, cob), (-1, "pdo"))
        model = s.network_of(bus)  # each bus its own PDO configuration
        cfg = configs[bus]
        st = g.hist.stats() if g.hist.n else dict.fromkeys(("min", "median", "max"), float("nan"))
        span = (g.last_t or 0) - (g.first_t or 0)
        rate = (g.count - 1) / span if span > 0 else float("nan")
        params = cfg.pdo_params(cob, g.last_t or 0.0) if cfg is not None else None
        et = inh = tt = "-"
        if params is not None:
            pnode, pc = params
            comm = (0x1800 if pc.direction == "tx" else 0x1400) + pc.number - 1
            t_end = g.last_t or 0.0
            et = _pdo_param(model, pnode, comm, 5, t_end, pc.event_timer, lambda v: f"{v} ms")
            inh = _pdo_param(
                model, pnode, comm, 3, t_end, pc.inhibit_time, lambda v: f"{v / 10:g} ms"
            )
            tt = str(pc.transmission_type)
        rows.append(
            [
                f"0x{cob:03X}",
                s.who(bus, node).removeprefix("node "),
                name,
                f"{g.count:,}",
                *(
                    (_ms(rate), _ms(st["min"]), _ms(st["median"]), _ms(st["max"]))
                    if s.timed  # a log without times has no rates nor gaps
                    else ("-", "-", "-", "-")
                ),
                tt,
                et,
                inh,
                per_cob.get((bus if s.several else "", cob), 0),
            ]
        )
    return {"rows": rows}


def _pdo_param(model, node: int, index: int, sub: int, t: float, value: int, text) -> str:
    """A PDO timing parameter and where it comes from; 0 means off (CiA 301) unless only
    the profile says 0, which is unknown (docs/network-file.md, as the checks read it)."""
    k = model.known(node, index, sub, t)
    if k is None:  # nothing in the log, a file or a profile sets it
        return f"{text(value)} (default)" if value else "not known"
    if not value:
        return "unknown (profile says 0)" if k.source == "profile" else f"off ({k.source})"
    return f"{text(value)} ({k.source})"


def signals(s, figs: Figures) -> dict | None:
    if not s.series:
        return None
    by_pdo: dict[tuple, list] = defaultdict(list)
    for key, ser in s.series.items():
        by_pdo[key[:4]].append(ser)
    out = []
    for (bus, node, pdo, cob), series in sorted(by_pdo.items()):
        title = f"{_node_name(node, bus if s.several else None)} {pdo.upper()} (0x{cob:03X})"
        x0, _, x = s.axis()
        out.append(figs.add(plots.signals(series, x0, title, x)))
    return {"plots": out, "dropped": s.series_dropped}


def drive_states(s, figs: Figures) -> dict | None:
    """CiA 402 drive states, one lane per drive, from the event log's `drive_state`
    events (`ReportSink._drive_states`); no section while the log has none."""
    if not s.drive_states:
        return None
    lanes = [(t, s.who(bus, n), state) for t, (bus, n), state in s.drive_states]
    x0, x_end, x = s.axis()
    fig = plots.state_timeline(lanes, x0, x_end, "Drive state per node", x)
    return {"plot": figs.add(fig)}


def sync_latency(s, figs: Figures) -> dict | None:
    """Synchronous PDOs after SYNC: the latency's figures per COB-ID beside the window
    0x1007 and the margin left, and its histogram with the window marked."""
    checker = s.run.checker
    if checker is None or not s.timed:
        return None
    rows, figures = [], []
    for c in (checker, *checker.others):
        timing = c.timing
        for cob, st in timing.report()["sync_latency"].items():
            if not st.get("count"):
                continue
            who = s.who(c.bus if s.several else None, st["node"])
            window = st["window_ms"]
            rows.append(
                [
                    f"0x{cob:03X}",
                    who.removeprefix("node "),
                    st["pdo"].upper(),
                    st["type"],
                    f"{st['count']:,}",
                    *(_ms(st[k], 3) for k in ("min", "median", "p99", "max", "jitter")),
                    "-" if window is None else f"{window:g}",
                    "-" if st["margin_ms"] is None else _ms(st["margin_ms"], 3),
                ]
            )
            title = f"0x{cob:03X} ({who} {st['pdo'].upper()}) latency after SYNC"
            marks = [window] if window else []
            figures.append(figs.add(plots.histogram(timing.sync_latency[cob], title, "ms", marks)))
    return {"rows": rows, "plots": figures} if rows else None


def _commissioning(s) -> list:
    """(bus, the run's `decode.commissioning.Commissioning`) of each bus: the one producer
    of boot stories and LSS steps (the event log and JSONL read the same)."""
    from cananalyze.decode.commissioning import Commissioning

    run = s.run
    if run is None or run.decoder is None:
        return []
    return run.decoder.processors_of(Commissioning)


def boot(s, figs: Figures) -> dict | None:
    """Each node's boot stories (CiA 302-2, decode/boot): its steps, where it stopped and
    the boot error status in words; only nodes whose boot-up the log holds."""
    from cananalyze.decode.boot import STATUS

    out = []
    nodes = s.run.options.nodes  # --node: those nodes' stories only
    for bus, c in _commissioning(s):
        bus = bus if s.several else None
        profiles = _profiles(s.network_of(bus))
        for story in c.stories:
            if story.t_boot is None or (nodes is not None and story.node not in nodes):
                continue
            name = _node_name(story.node, bus)
            device = profiles.get(story.node)
            letter = story.status
            steps = [[_when(s, t), step, result, detail] for t, step, result, detail in story.steps]
            out.append(
                {
                    "id": f"boot-{_node_id(story.node, bus)}-{story.life}",
                    "name": name + (f" ({device})" if device else ""),
                    "life": story.life,
                    "at": f" at {_rel(s, story.t_boot)}" if s.timed else "",  # no times: none
                    "result": story.result,
                    "verdict": story.verdict,
                    "stopped_at": story.stopped_at or "-",
                    "status": f"{letter}: {STATUS[letter]}" if letter in STATUS else "-",
                    "steps": steps,
                    "writes": f"{story.writes} writes ok, {len(story.aborts)} aborted",
                }
            )
    return {"stories": out} if out else None


def _when(s, t: float | None) -> str:
    """A time from the log's start; "-" in a log without times (every frame has one)."""
    return _rel(s, t) if s.timed else "-"


def _profiles(model) -> dict[int, str]:
    from cananalyze.decode.node_tally import node_profiles

    if model is None:
        return {}
    return {n: str(p) for n, (p, _) in node_profiles(model).items()}


def _hex(v) -> str:
    return "-" if v is None else f"0x{v:08X}" if isinstance(v, int) else str(v)


def lss(s, figs: Figures) -> dict | None:
    """LSS (CiA 305) steps with their results, and which identity got which node-ID when
    (decode/lss, as `load().lss` and `load().lss_assignments`)."""
    from cananalyze.decode.lss import PARTS, identity_text

    steps, assigned = [], []
    if s.run.options.nodes is not None:  # --node: LSS steps belong to no node
        return None
    for bus, c in _commissioning(s):
        where = [bus] if s.several else []
        for ev in c.lss_events:
            steps.append(
                [
                    *where,
                    _when(s, ev.t),
                    ev.step,
                    ev.result,
                    identity_text(ev.identity) or "-",
                    "-" if ev.node_id is None else ev.node_id,
                    ev.detail or "-",
                ]
            )
        for a in c.assignments:
            assigned.append(
                [
                    *where,
                    _when(s, a["t"]),
                    *(_hex(a.get(p)) for p in PARTS),
                    "-" if a.get("node_id") is None else a["node_id"],
                    "yes" if a.get("stored") else "no",
                ]
            )
    if not steps:
        return None
    bus = ["bus"] if s.several else []
    return {
        "steps_head": [*bus, "time", "step", "result", "identity", "node-ID", "detail"],
        "steps": steps,
        "assigned_head": [
            *bus,
            "time",
            "vendor-ID",
            "product code",
            "revision",
            "serial",
            "node-ID",
            "stored",
        ],
        "assigned": assigned,
    }


MAX_NET_NODES = 48  # a picture beyond that is unreadable; the table lists every relation
OTHER = -1  # the network page's circle for a producer or consumer no configuration names


def network(s, figs: Figures) -> dict | None:
    """The network page: per bus, who produces which PDO and who consumes it, and who
    watches whose heartbeat, as the configuration in force at the end of the log says
    (the log's SDO writes, the network file, the profiles: `ModelConfig`, as the checks
    read it); what the `consistency` rule found contradictory is drawn in red."""
    configs = _Configs(s)
    t = s.t_last or 0.0
    out, rows = [], []
    for bus in sorted(s.buses) if s.several else [""]:
        cfg = configs[bus]
        if cfg is None:
            continue
        red_cob, red_node = set(), set()
        for f in s.findings:
            if f.rule == "consistency" and (not s.several or (f.bus or "") == bus):
                if f.cob_id is not None:
                    red_cob.add(f.cob_id)
                if f.node is not None:
                    red_node.add(f.node)
        producers: dict[int, list[int]] = defaultdict(list)
        consumers: dict[int, list[int]] = defaultdict(list)
        watches: list[tuple[int, int, float]] = []  # (producer, consumer, ms)
        nodes = set()
        for node in cfg.configured_nodes():
            for comm, _, value, valid in cfg.pdo_cob_ids(node, t):
                cob = value & 0x1FFFFFFF if value & 0x20000000 else value & 0x7FF
                if valid and cob:
                    (producers if comm >= 0x1800 else consumers)[cob].append(node)
                    nodes.add(node)
            for producer, ms in cfg.heartbeat_consumers(node, t).items():
                watches.append((producer, node, ms))
                nodes.update((producer, node))
        if not nodes:
            continue
        who = [n for n in sorted(nodes)][:MAX_NET_NODES]
        size = 360 if len(who) <= 12 else 520
        r = size / 2 - 40
        at = {
            n: (
                round(size / 2 + r * math.sin(2 * math.pi * k / len(who)), 1),
                round(size / 2 - r * math.cos(2 * math.pi * k / len(who)), 1),
            )
            for k, n in enumerate(who)
        }
        at[OTHER] = (size / 2, size / 2)
        edges: list[dict] = []

        b = [bus] if s.several else []
        for cob in sorted(set(producers) | set(consumers)):
            red = cob in red_cob
            cls = "pdo red" if red else "pdo"
            # a side the configuration does not name (the master, a node not declared):
            # the "other" circle in the middle
            for p in producers.get(cob) or [OTHER]:
                for c in consumers.get(cob) or [OTHER]:
                    edges += _edge(at, p, c, f"0x{cob:03X}", cls)
            rows.append(
                [
                    *b,
                    "PDO",
                    ", ".join(map(str, producers.get(cob, []))) or "-",
                    ", ".join(map(str, consumers.get(cob, []))) or "-",
                    f"0x{cob:03X}",
                    "contradiction (consistency)" if red else "",
                ]
            )
        for producer, consumer, ms in sorted(watches):
            red = consumer in red_node and producer in red_node
            edges += _edge(at, producer, consumer, f"{ms:g} ms", "hb red" if red else "hb")
            rows.append([*b, "heartbeat watch", str(producer), str(consumer), "-", ""])
        out.append(
            {
                "label": bus,
                "size": size,
                "edges": edges,
                "nodes": [
                    {"x": at[n][0], "y": at[n][1], "label": str(n), "cls": "red" * (n in red_node)}
                    for n in who
                ]
                + [{"x": size / 2, "y": size / 2, "label": "other", "cls": "other"}],
            }
        )
    if not out:
        return None
    head = (["bus"] if s.several else []) + ["relation", "from", "to", "COB-ID", "note"]
    return {"buses": out, "head": head, "rows": rows}


def _edge(at: dict, a: int, b: int, label: str, cls: str) -> list[dict]:
    """An arrow from node a's circle to node b's (none when either is not drawn)."""
    if a not in at or b not in at or a == b:
        return []
    (x1, y1), (x2, y2) = at[a], at[b]
    k = 20 / (math.hypot(x2 - x1, y2 - y1) or 1.0)  # from circle edge to circle edge
    return [
        {
            "x1": round(x1 + (x2 - x1) * k, 1),
            "y1": round(y1 + (y2 - y1) * k, 1),
            "x2": round(x2 - (x2 - x1) * k, 1),
            "y2": round(y2 - (y2 - y1) * k, 1),
            "lx": round((x1 + x2) / 2, 1),
            "ly": round((y1 + y2) / 2 - 3, 1),
            "label": label,
            "cls": cls,
        }
    ]


SECTIONS = [verdict, buses, findings, differences, nodes, boot, lss, sdo, emcy, pdos]
SECTIONS += [network, sync_latency]
SECTIONS += [signals, drive_states]


def _abort_code(r: dict) -> str:
    """An abort code as hex: 8 digits (SDO), 2 for CANopen FD's one-byte USDO codes."""
    code = r.get("abort_code")
    if not isinstance(code, int):
        return "-"
    width = 2 if str(r.get("protocol") or "").startswith("usdo") else 8
    return f"0x{code:0{width}X}"
