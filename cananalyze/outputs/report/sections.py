"""The report's sections, in reading order, as HTML fragments.

Each takes the ReportSink's summaries and a `Figures` that collects the plots.
Texts are escaped with `html.escape`; nothing here judges the log: the verdict
and every alarm are the Checker's findings, the tables show what was measured
beside what was configured.
"""

from __future__ import annotations

import html
from collections import defaultdict

from cananalyze.checks.model_config import ModelConfig
from cananalyze.core.finding import show
from cananalyze.outputs.junit import format_finding
from cananalyze.outputs.report import plots

esc = html.escape


class Figures:
    """Plot placeholders and their figures (`plots`), drawn by the page's loader."""

    def __init__(self) -> None:
        self.items: list[tuple[str, dict]] = []

    def add(self, fig: dict, cls: str = "plot") -> str:
        pid = f"fig{len(self.items)}"
        self.items.append((pid, fig))
        return f'<div class="{cls}" id="{pid}"></div>'


def _table(head: list[str], rows: list[list], cls: str = "") -> str:
    th = "".join(f"<th>{esc(h)}</th>" for h in head)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f'<table class="{cls}"><thead><tr>{th}</tr></thead><tbody>{body}</tbody></table>'


def _ms(v: float | None, nd: int = 2) -> str:
    if v is None or v != v or v in (float("inf"), float("-inf")):
        return "-"
    return f"{v:.{nd}f}"


def _rel(s, t: float | None) -> str:
    return "-" if t is None else f"{t - s.t0:+.3f} s"


def verdict(s, figs: Figures) -> str:
    failing = [f for f in s.findings if f.fails]
    rules = s.rules
    counts: dict[str, int] = {}
    for r in rules:  # a rules file's assertions share a name: one entry each, counted
        counts[r.name] = counts.get(r.name, 0) + 1
    names = ", ".join(f"{n} ×{k}" if k > 1 else n for n, k in counts.items())
    ok = not failing
    word = "PASS" if ok else "FAIL"
    dur = (s.t_last - s.t_first) if s.t_first is not None else 0.0
    text = (
        f"{len(rules)} rules: {len(failing)} violation(s), {len(s.findings) - len(failing)} "
        f"note(s) in {s.frames:,} frames over {dur:.1f} s"
    )
    skipped = s.run.problems.count
    skip = f"<p class=warn>{skipped} unreadable lines/records skipped</p>" if skipped else ""
    load = figs.add(plots.bus_load(s.buses, s.t0, s.bitrate)) if s.buses else ""
    return (
        f'<section id="verdict"><div class="verdict {"pass" if ok else "fail"}" id="verdict-banner">'
        f"<b>{word}</b> {esc(text)}</div><p class=small>Rules: {esc(names) or 'none'}</p>"
        f"{skip}{load}</section>"
    )


def buses(s, figs: Figures) -> str:
    rows = []
    for ch, b in s.buses.items():
        unit = 100.0 / s.bitrate if s.bitrate else 1e-3
        u = "%" if s.bitrate else " kbit/s"
        rows.append(
            [
                esc(ch),
                f"{b.frames:,}",
                f"{b.errors:,}",
                f"{b.load.mean * unit:.2f}{u}",
                f"{b.load.peak * unit:.2f}{u}",
            ]
        )
    note = "" if s.bitrate else "<p class=small>Give --bitrate for the load in percent.</p>"
    return (
        '<section id="buses"><h2>Buses</h2>'
        + _table(["channel", "frames", "error frames", "mean load", "peak load (100 ms)"], rows)
        + note
        + "<p class=small>Nominal bits without stuff bits: a lower bound.</p></section>"
    )


# findings listed per node and rule: all are counted, `check --json`/JUnit hold every one.
# 50 lines say what a group is; at 200 the list was 1.8 of a 10M-frame page's 5.4 MB
LISTED = 50


def _without_why(f) -> str:
    """A finding's line (`format_finding`, as JUnit and check print it) without its
    explanation, which the group shows once."""
    text = format_finding(f)
    return text[: -len(f.why)].rstrip() if f.why and text.endswith(f.why) else text


def findings(s, figs: Figures) -> str:
    if not s.findings:
        return '<section id="findings"><h2>Findings</h2><p>No findings.</p></section>'
    groups: dict[tuple, list] = defaultdict(list)
    for f in s.findings:
        groups[(f.bus or "", f.node is None, f.node or 0, f.rule)].append(f)
    parts = ['<section id="findings"><h2>Findings by node and rule</h2>']
    for (bus, _, node, rule), fs in sorted(groups.items()):
        who = "bus" if fs[0].node is None else f"node {node}"
        who = f"{bus} {who}" if bus else who  # several buses: "can1 node 5"
        sev = "error" if any(f.fails for f in fs) else fs[0].severity
        first = fs[0]
        shown = fs[:LISTED]
        # each explanation once, above the list: repeated on every line it made most of a
        # 10M-frame page (3.4 of 7 MB for 16 nodes' 86k SYNC and EMCY findings)
        whys = "".join(f"<p class=why>{esc(w)}</p>" for w in dict.fromkeys(f.why for f in shown))
        items = "".join(f"<li>{esc(_without_why(f))}</li>" for f in shown)
        more = (
            f"<li>... and {len(fs) - LISTED} more (every one in <code>check --json</code> "
            "and JUnit)</li>"
            if len(fs) > LISTED
            else ""
        )
        parts.append(
            f'<details class="finding {esc(sev)}"><summary><b>{esc(who)}</b> · {esc(rule)} · '
            f"{len(fs)} finding(s), first at {_rel(s, first.t)}: {esc(first.message)} "
            f"(measured {esc(show(first.measured))}, expected {esc(show(first.expected))})"
            f"</summary>{whys}<ul>{items}{more}</ul></details>"
        )
    parts.append("</section>")
    return "".join(parts)


def _node_name(n: int, bus: str | None) -> str:
    return f"Node {n}" if bus is None else f"{bus} node {n}"


def _node_id(n: int, bus: str | None) -> str:
    return f"node-{n}" if bus is None else f"node-{bus}-{n}"


def nodes(s, figs: Figures) -> str:
    from cananalyze.decode.node_tally import bus_profiles, node_profiles

    model = s.run.network
    rows = s.tally.rows(
        node_profiles(model) if model is not None else {}, bus_profiles(s.run.decoder)
    )
    configs = _Configs(s)
    parts = ['<section id="nodes"><h2>Nodes</h2>']
    if s.states:
        lanes = [(t, s.who(bus, n), state) for t, (bus, n), state in s.states]
        parts.append(figs.add(plots.state_timeline(lanes, s.t0, s.t_last or s.t0)))
    if s.states_dropped:
        parts.append(f"<p class=warn>{s.states_dropped} more NMT state changes not drawn</p>")
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
        parts.append(
            f'<div class="node" id="{_node_id(n, bus)}"><h3>{esc(_node_name(n, bus))}: '
            f"{esc(str(dev))}</h3>"
            f"<p>Identified by: {esc(str(how))}{'; ' + esc(ident) if ident else ''}. "
            f"{row['frames']:,} frames; last NMT state {esc(str(row.get('last_state') or '-'))}.</p>"
        )
        cfg = configs[bus]  # that bus's configuration, as its checker judged
        for kind in ("heartbeat", "guarding"):
            g = s.errctl.get((kind, n) if bus is None else (kind, n, bus))
            if g is None or g.hist.count == 0:
                continue
            conf = _configured(cfg, kind, n, g) if cfg is not None else []
            h = g.hist
            expect = ", ".join(sorted({_ms(v, 0) for _, v in conf})) or "not configured"
            parts.append(
                f"<p>{kind} period: n={h.count:,} min {_ms(h.min)} median {_ms(h.quantile(0.5))} "
                f"mean {_ms(h.mean)} p99 {_ms(h.quantile(0.99))} max {_ms(h.max)} "
                f"jitter (std) {_ms(h.std)} ms; configured {expect} ms</p><div class=pair>"
            )
            who = _node_name(n, bus)
            parts.append(figs.add(plots.period(g, s.t0, kind, who, conf), "plot half"))
            marks = sorted({v for _, v in conf})
            parts.append(
                figs.add(
                    plots.histogram(h, f"{who} {kind} period histogram", "period (ms)", marks),
                    "plot half",
                )
            )
            parts.append("</div>")
        parts.append("</div>")
    parts.append("</section>")
    return "".join(parts)


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


def sdo(s, figs: Figures) -> str:
    if not s.sdo_count:
        return ""
    from cananalyze.outputs.report.accum import LogHistogram

    rows = []
    for (bus, n), (ok, bad, h) in sorted(_sdo_by_bus(s).items()):
        who = esc(s.who(bus, n)) if s.several else n
        if h is not None and h.count:
            rows.append(
                [
                    who,
                    ok + bad,
                    bad,
                    _ms(h.min),
                    _ms(h.quantile(0.5)),
                    _ms(h.quantile(0.99)),
                    _ms(h.max),
                ]
            )
        else:
            rows.append([who, ok + bad, bad, "-", "-", "-", "-"])
    parts = ['<section id="sdo"><h2>SDO transfers</h2>']
    parts.append(
        _table(["node", "transfers", "aborts", "min ms", "median ms", "p99 ms", "max ms"], rows)
    )

    allh = LogHistogram()
    for h in s.sdo_latency.values():
        allh.merge(h)
    if allh.count:
        parts.append(figs.add(plots.histogram(allh, "SDO latency", "latency (ms)")))
    if s.aborts:
        arows = [
            [
                _rel(s, r.get("t")),
                esc(s.who(s.first_bus(bus), r["node"]))
                if s.several and r.get("node") is not None
                else r.get("node"),
                esc(str(r.get("direction") or "")),
                f"0x{r.get('index', 0):04X}:{r.get('subindex', 0):02X}",
                esc(str(r.get("name") or "")),
                esc(f"0x{r['abort_code']:08X}" if isinstance(r.get("abort_code"), int) else "-"),
                esc(str(r.get("abort_text") or r.get("result") or "")),
            ]
            for bus, r in s.aborts
        ]
        parts.append("<h3>Aborts and timeouts</h3>")
        parts.append(_table(["time", "node", "direction", "object", "name", "code", "text"], arows))
    parts.append("</section>")
    return "".join(parts)


def _sdo_by_bus(s) -> dict:
    """(bus, node) -> [ok, aborts, latency histogram]: the transfers counted before a
    second bus was seen (bus "") are the first bus's."""
    from cananalyze.outputs.report.accum import LogHistogram

    out: dict = {}
    for (bus, n), (ok, bad) in s.sdo_count.items():
        item = out.setdefault((s.first_bus(bus), n), [0, 0, LogHistogram()])
        item[0] += ok
        item[1] += bad
        h = s.sdo_latency.get((bus, n))
        if h is not None:
            item[2].merge(h)
    return out


def emcy(s, figs: Figures) -> str:
    if not s.emcys:
        return ""
    active: dict[tuple[str, int], list] = {}  # (bus, node): node 5 on each bus its own
    rows = []
    resets = sorted(s.bootups)
    for t, bus, node, code, reg, text in sorted(s.emcys):
        if code == 0:
            for item in active.pop((bus, node), []):
                item[2] = f"{t - item[0]:.3f} s"
            continue
        item = [t, s.who(bus, node), "still active at the end of the log", code, reg, text]
        active.setdefault((bus, node), []).append(item)
        rows.append(item)
    for t, bus, node in resets:  # a boot-up clears the node's errors
        for item in list(active.get((bus, node), [])):
            if item[0] < t:
                item[2] = f"{t - item[0]:.3f} s (until boot-up)"
                active[(bus, node)].remove(item)
    out = [
        [
            _rel(s, t),
            who.removeprefix("node "),
            f"0x{code:04X}" if code >= 0 else "-",
            f"0x{reg:02X}" if reg >= 0 else "-",
            esc(text),
            esc(dur),
        ]
        for t, who, dur, code, reg, text in rows
    ]
    more = len(s.emcys) < s.emcy_count
    return (
        '<section id="emcy"><h2>EMCY</h2>'
        + _table(["time", "node", "code", "register", "meaning", "active for"], out)
        + (f"<p class=warn>{s.emcy_count - len(s.emcys)} more EMCYs not listed</p>" if more else "")
        + "</section>"
    )


def pdos(s, figs: Figures) -> str:
    if not s.pdos:
        return ""
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
        h = g.hist
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
                _ms(rate),
                _ms(h.min),
                _ms(h.quantile(0.5)),
                _ms(h.max),
                tt,
                et,
                inh,
                per_cob.get((bus if s.several else "", cob), 0),
            ]
        )
    head = ["COB-ID", "node", "PDO", "frames", "rate Hz", "min gap ms", "median gap ms"]
    head += ["max gap ms", "transmission type", "event timer", "inhibit time", "findings"]
    return (
        '<section id="pdo"><h2>PDO rates</h2>'
        + _table(head, rows)
        + "<p class=small>Configured values as known at the end of the log, with where each "
        "comes from: log (an SDO write or read), file (network or rules file, --device/--eds) "
        "or profile (EDS/DCF).</p></section>"
    )


def _pdo_param(model, node: int, index: int, sub: int, t: float, value: int, text) -> str:
    """A PDO timing parameter and where it comes from; 0 means off (CiA 301) unless only
    the profile says 0, which is unknown (docs/network-file.md, as the checks read it)."""
    k = model.known(node, index, sub, t)
    source = k.source if k is not None else "network file"
    if not value:
        return "unknown (profile says 0)" if source == "profile" else f"off ({source})"
    return f"{text(value)} ({source})"


def signals(s, figs: Figures) -> str:
    if not s.series:
        return ""
    by_pdo: dict[tuple, list] = defaultdict(list)
    for key, ser in s.series.items():
        by_pdo[key[:4]].append(ser)
    parts = ['<section id="signals"><h2>Signals per PDO</h2>']
    for (bus, node, pdo, cob), series in sorted(by_pdo.items()):
        title = f"{_node_name(node, bus if s.several else None)} {pdo.upper()} (0x{cob:03X})"
        parts.append(figs.add(plots.signals(series, s.t0, title)))
    if s.series_dropped:
        parts.append(f"<p class=warn>{s.series_dropped} more signals not plotted</p>")
    parts.append("</section>")
    return "".join(parts)


def drive_states(s, figs: Figures) -> str:
    """CiA 402 drive states, one lane per drive, from the event log's `drive_state`
    events (`ReportSink._drive_states`); no section while the log has none."""
    if not s.drive_states:
        return ""
    lanes = [(t, s.who(bus, n), state) for t, (bus, n), state in s.drive_states]
    fig = plots.state_timeline(lanes, s.t0, s.t_last or s.t0, "Drive state per node")
    return '<section id="drive"><h2>Drive states (CiA 402)</h2>' + figs.add(fig) + "</section>"


SECTIONS = [verdict, buses, findings, nodes, sdo, emcy, pdos, signals, drive_states]
