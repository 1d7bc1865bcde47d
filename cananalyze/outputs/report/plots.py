"""The report's plots as plotly figures (the page embeds plotly.js once, `page.py`).

Figures are written as plotly's JSON figure documents ({"data": traces, "layout": ...})
directly: building them through `plotly.graph_objects` validated and deep-copied every
property, 2.5 s for fifty plots, more than the statistics of a million frames. Arrays
travel as plotly.js typed arrays ({"dtype": "f4", "bdata": base64}): float32 is finer
than a pixel, and a thousand-point envelope costs 11 kB. Times are seconds from the
log's first frame.
"""

from __future__ import annotations

import base64
import json

import numpy as np

from .accum import Envelope, LogHistogram

HEIGHT = 260
NMT_COLOURS = {
    "operational": "#2ca02c",
    "pre-operational": "#1f77b4",
    "stopped": "#d62728",
    "initialising": "#7f7f7f",
}


def typed(values) -> dict:
    """A plotly.js typed array of float32."""
    a = np.ascontiguousarray(values, dtype="<f4")
    return {"dtype": "f4", "bdata": base64.b64encode(a.tobytes()).decode("ascii")}


def _fig(traces: list[dict], title: str, x: str, y: str, **layout) -> str:
    base = {
        "title": {"text": title, "font": {"size": 14}},
        "height": layout.pop("height", HEIGHT),
        "margin": {"l": 60, "r": 20, "t": 36, "b": 40},
        "template": {"layout": {"plot_bgcolor": "white", "paper_bgcolor": "white"}},
        "xaxis": {"title": {"text": x}, "gridcolor": "#eee", **layout.pop("xaxis", {})},
        "yaxis": {"title": {"text": y}, "gridcolor": "#eee"},
        "showlegend": layout.pop("showlegend", len(traces) > 1),
    }
    base.update(layout)
    return json.dumps({"data": traces, "layout": base}, separators=(",", ":"))


def envelope_trace(env: Envelope, t0: float, name: str, scale: float = 1.0) -> dict:
    t, v = env.points()
    return {
        "type": "scatter",
        "mode": "lines",
        "name": name,
        "x": typed(t - t0),
        "y": typed(v * scale),
        "line": {"width": 1},
    }


def bus_load(buses: dict, t0: float, bitrate: int | None) -> str:
    scale = 100.0 / bitrate if bitrate else 1e-3
    unit = "% of bitrate" if bitrate else "kbit/s"
    traces = [envelope_trace(b.load.load, t0, ch, scale) for ch, b in buses.items()]
    return _fig(traces, "Bus load per channel (100 ms windows)", "time (s)", unit)


def period(gaps, t0: float, kind: str, node: int, configured: list[tuple[float, float]]) -> str:
    """The heartbeat (or guarding) period over time, against the configured value."""
    traces = [envelope_trace(gaps.over_time, t0, "measured")]
    if configured:
        xs = [t - t0 for t, _ in configured] + [(gaps.last_t or t0) - t0]
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
    return _fig(traces, f"Node {node} {kind} period", "time (s)", "period (ms)")


def histogram(hist: LogHistogram, title: str, x: str, marks: list[float] | None = None) -> str:
    left, width, count = hist.bars()
    bars = {
        "type": "bar",
        "name": "count",
        "x": (left + width / 2).tolist(),
        "y": count.tolist(),
        "width": width.tolist(),
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
    # a log axis: 0.2 % bins are equally wide, and a dropout shows beside the jitter
    return _fig([bars], title, x, "count", shapes=shapes, bargap=0, xaxis={"type": "log"})


def state_timeline(
    states: list[tuple[float, int, str]], t0: float, t_end: float, title: str = "NMT state per node"
) -> str:
    """One lane per node: each state (NMT, CiA 402 drive) from its change to the next."""
    by_node: dict[int, list] = {}
    for t, node, state in sorted(states):
        by_node.setdefault(node, []).append((t, state))
    segs: dict[str, list] = {}
    for node, seq in by_node.items():
        for k, (t, state) in enumerate(seq):
            end = seq[k + 1][0] if k + 1 < len(seq) else t_end
            segs.setdefault(state, []).append((f"node {node}", t - t0, max(end - t, 1e-6)))
    traces = [
        {
            "type": "bar",
            "orientation": "h",
            "name": state,
            "y": [s[0] for s in rows],
            "base": [s[1] for s in rows],
            "x": [s[2] for s in rows],
            "marker": {"color": NMT_COLOURS.get(state.split()[0])},
            "hovertemplate": "%{y}: " + state + " from %{base:.3f} s for %{x:.3f} s<extra></extra>",
        }
        for state, rows in segs.items()
    ]
    h = max(HEIGHT, 60 + 28 * len(by_node))
    return _fig(traces, title, "time (s)", "", barmode="overlay", height=h, showlegend=True)


def signals(series: list, t0: float, title: str) -> str:
    units = sorted({s.unit or "" for s in series})
    y = ", ".join(u for u in units if u) or "value"
    traces = [
        envelope_trace(s.env, t0, f"{s.name} ({s.unit})" if s.unit else s.name) for s in series
    ]
    return _fig(traces, title, "time (s)", y)
