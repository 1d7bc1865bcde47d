"""The report's plots as plotly figures (the page embeds plotly.js once, `page.py`).

Figures are plotly's figure documents ({"data": traces, "layout": ...}) as dicts:
building them through `plotly.graph_objects` validated and deep-copied every property,
2.5 s for fifty plots, more than the statistics of a million frames. Plotted arrays are
`encode.Packed` (rounded below a pixel, sent as integers in the page's compressed
figures): a thousand-point envelope costs a few kB. Times are seconds from the log's
first frame, rounded to the microsecond; periods and latencies are ms, to the µs.

Texts in a figure are plotly's own markup: it draws <b>, <br>, <a href> and more, and
reads entities. The names in them come from the log and the files given (channel,
node, signal and PDO names, units), so `_fig` writes every text as `plain` text.
"""

from __future__ import annotations

import numpy as np

from cananalyze.checks.streamstats import StreamStats
from cananalyze.outputs.report.accum import Envelope
from cananalyze.outputs.report.encode import Packed

HEIGHT = 260
# min/max buckets across a full-width plot (about one per pixel column), shared by its
# lines down to a floor; half-width plots get half
PLOT_BUCKETS = 1000
LINE_BUCKETS = 250
NMT_COLOURS = {
    "operational": "#2ca02c",
    "pre-operational": "#1f77b4",
    "stopped": "#d62728",
    "initialising": "#7f7f7f",
}


US = 1e-6  # s: the logs' time stamps' resolution (candump, ASC, TRC), plotted times' step
US_MS = 1e-3  # the same in ms: periods measured between time stamps


def sig(values, digits: int = 6) -> list[float]:
    """Floats to `digits` significant digits: a histogram's log-spaced bars, as JSON."""
    return [float(f"{v:.{digits}g}") for v in np.asarray(values, np.float64).tolist()]


def _share(lines: int) -> int:
    """Each line's buckets when `lines` share a full-width plot."""
    return max(PLOT_BUCKETS // max(lines, 1), LINE_BUCKETS)


def plain(text: str) -> str:
    """`text` as plotly draws it, character for character: '&', '<' and '>' as entities
    (plotly turns them back into the characters), so no part of it is read as markup."""
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def _fig(traces: list[dict], title: str, x: str, y: str, **layout) -> dict:
    """The figure; the one place its texts are made `plain`: the title, the axes'
    titles, the traces' names and category values (the state lanes). A hover template
    is ours (it names its trace as %{fullData.name}, made plain here)."""
    for trace in traces:
        if "name" in trace:
            trace["name"] = plain(trace["name"])
        for k in ("x", "y"):
            values = trace.get(k)
            if isinstance(values, list) and any(isinstance(v, str) for v in values):
                trace[k] = [plain(v) if isinstance(v, str) else v for v in values]
    base = {
        # at the left: plotly's mode bar (top right) never covers it, even on half a page
        "title": {"text": plain(title), "font": {"size": 14}, "x": 0.01, "xanchor": "left"},
        "height": layout.pop("height", HEIGHT),
        "margin": {"l": 60, "r": 20, "t": 36, "b": 40},
        "template": {"layout": {"plot_bgcolor": "white", "paper_bgcolor": "white"}},
        "xaxis": {"title": {"text": plain(x)}, "gridcolor": "#eee", **layout.pop("xaxis", {})},
        "yaxis": {"title": {"text": plain(y)}, "gridcolor": "#eee"},
        "showlegend": layout.pop("showlegend", len(traces) > 1),
    }
    base.update(layout)
    return {"data": traces, "layout": base}


def envelope_trace(
    env: Envelope,
    t0: float,
    name: str,
    scale: float = 1.0,
    resolution: float | None = None,
    buckets: int = PLOT_BUCKETS,
    stepped: bool = False,
    gaps: bool = False,
) -> dict:
    """A min/max envelope as a line of at most `buckets` buckets; `resolution`: the
    value's finest meaningful step; `stepped`: drawn as steps (each value held until the
    next), for integer values; `gaps`: a pause in the series breaks its line."""
    t, v = env.points(buckets)
    if gaps:
        t, v = with_gaps(t, v)
    line = {"width": 1, "shape": "hv"} if stepped else {"width": 1}
    return {
        "type": "scatter",
        "mode": "lines",
        "name": name,
        "x": Packed(t - t0, US),
        "y": Packed(v * scale, resolution),
        "line": line,
    }


GAP = 3.0  # a pause over 3 times the series' usual spacing between points is a gap


def with_gaps(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A NaN value (plotly's break in a line) between two points further apart than
    GAP times the usual (median) spacing of the series' points: a signal that stopped
    coming is not drawn as a slope (or a held step) across the time it was missing."""
    at = np.unique(t)
    if at.size < 3:
        return t, v
    step = np.diff(at)
    usual = float(np.median(step))
    far = at[1:][step > GAP * usual]  # the first point after each gap
    if far.size == 0 or usual <= 0:
        return t, v
    cut = np.searchsorted(t, far)
    t = np.insert(t, cut, t[cut - 1])
    v = np.insert(v.astype(np.float64), cut, np.nan)
    return t, v


def bus_load(buses: dict, t0: float, bitrate: int | None) -> dict:
    scale = 100.0 / bitrate if bitrate else 1e-3
    unit = "% of bitrate" if bitrate else "kbit/s"
    most = _share(len(buses))
    traces = [  # a pause in traffic breaks the line: no slope across it
        envelope_trace(b.load.load, t0, ch, scale, buckets=most, gaps=True)
        for ch, b in buses.items()
    ]
    return _fig(traces, "Bus load per channel (100 ms windows)", "time (s)", unit)


def period(
    gaps, t0: float, kind: str, node: int | str, configured: list[tuple[float, float]]
) -> dict:
    """The heartbeat (or guarding) period over time, against the configured value; to
    the µs (the gaps between epoch time stamps carry float noise below it)."""
    half = PLOT_BUCKETS // 2  # drawn beside its histogram
    measured = envelope_trace(gaps.over_time, t0, "measured", resolution=US_MS, buckets=half)
    # a period is drawn over the interval it measures (from the previous frame to this
    # one): a dropout is a plateau at its length, not a slope towards it
    measured["line"]["shape"] = "vh"
    traces = [measured]
    if configured:
        xs = [round(t - t0, 6) for t, _ in configured] + [round((gaps.last_t or t0) - t0, 6)]
        ys = [v for _, v in configured] + [configured[-1][1]]
        traces.append(
            {
                "type": "scatter",
                "mode": "lines",
                "name": "configured",
                "x": xs,
                "y": ys,
                "line": {"shape": "hv", "dash": "dash"},
            }
        )
    who = f"Node {node}" if isinstance(node, int) else node  # "can1 node 5" (several buses)
    return _fig(traces, f"{who} {kind} period", "time (s)", "period (ms)")


def histogram(hist: StreamStats, title: str, x: str, marks: list[float] | None = None) -> dict:
    left, width, count = hist.bars()
    bars = {
        "type": "bar",
        "name": "count",
        "x": sig(left + width / 2),
        "y": count.tolist(),
        "width": sig(width),
        "marker": {"line": {"width": 0}},
    }
    shapes = [
        {
            "type": "line",
            "x0": m,
            "x1": m,
            "y0": 0,
            "y1": 1,
            "yref": "paper",
            "line": {"dash": "dash", "color": "#d62728"},
        }
        for m in marks or []
    ]
    # a log axis: the log-scale bins are equally wide, and a dropout shows beside the jitter
    return _fig([bars], title, x, "count", shapes=shapes, bargap=0, xaxis={"type": "log"})


def state_timeline(
    states: list[tuple[float, int | str, str]],
    t0: float,
    t_end: float,
    title: str = "NMT state per node",
    x: str = "time (s)",
) -> dict:
    """One lane per node: each state (NMT, CiA 402 drive) from its change to the next.
    A lane is a node number, or its label ("can1 node 5" on a log of several buses)."""
    by_node: dict[int | str, list] = {}
    for t, node, state in sorted(states, key=lambda s: s[0]):
        by_node.setdefault(node, []).append((t, state))
    segs: dict[str, list] = {}
    for node, seq in by_node.items():
        lane = node if isinstance(node, str) else f"node {node}"
        for k, (t, state) in enumerate(seq):
            end = seq[k + 1][0] if k + 1 < len(seq) else t_end
            segs.setdefault(state, []).append((lane, t - t0, max(end - t, 1e-6)))
    traces = [
        {
            "type": "bar",
            "orientation": "h",
            "name": state,
            "y": [s[0] for s in rows],
            "base": Packed([s[1] for s in rows], US, exact=True),
            "x": Packed([s[2] for s in rows], US, exact=True),
            "marker": {"color": NMT_COLOURS.get(state.split()[0])},
            "hovertemplate": "%{y}: %{fullData.name} from %{base:.3f} s for %{x:.3f} s"
            "<extra></extra>",
        }
        for state, rows in segs.items()
    ]
    h = max(HEIGHT, 60 + 28 * len(by_node))
    return _fig(traces, title, x, "", barmode="overlay", height=h, showlegend=True)


def signals(series: list, t0: float, title: str, x: str = "time (s)") -> dict:
    units = sorted({s.unit or "" for s in series})
    y = ", ".join(u for u in units if u) or "value"
    most = _share(len(series))
    traces = [
        envelope_trace(
            s.env,
            t0,
            f"{s.name} ({s.unit})" if s.unit else s.name,
            buckets=most,
            stepped=s.stepped,
            gaps=True,
        )
        for s in series
    ]
    return _fig(traces, title, x, y)
