"""The page around the sections: styles, the embedded plotly.js and the loader.

plotly.js is 4.8 MB as text; the page carries it gzip-compressed (1.47 MB, 1.72 MB as
`encode.text7`) and the browser's own DecompressionStream unpacks it, so the file
stays small and needs no network. The plots' figures wait in one more such element
(`encode.Blob`: JSON and the arrays' integers) until plotly is loaded;
`document.body.dataset.ready` is set once all are drawn (the browser test waits for it).

The page is `templates.PAGE` (Jinja2, autoescape on): the sections' data and every
name in it are escaped there. `Markup` (passed as it is) only for what this module
makes itself: the CSS and the loader (constants) and the packed script text.
"""

from __future__ import annotations

import functools
from datetime import UTC, datetime

from markupsafe import Markup

from cananalyze.core.version import __version__
from cananalyze.outputs.report import templates
from cananalyze.outputs.report.encode import Blob, gzip7
from cananalyze.outputs.report.sections import SECTIONS, Figures

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:0 auto;max-width:1200px;
padding:12px 20px;color:#222}
h1{font-size:20px;margin:4px 0}h2{font-size:17px;border-bottom:1px solid #ddd;margin-top:28px}
h3{font-size:15px;margin:16px 0 4px}
.verdict{font-size:18px;padding:10px 14px;border-radius:6px;margin:8px 0}
.verdict.pass{background:#e3f5e1;border:1px solid #2ca02c}
.verdict.fail{background:#fde4e1;border:1px solid #d62728}
.small{font-size:12px;color:#666}.net line{stroke:#557;stroke-width:1.5}.net line.hb{stroke:#999;stroke-dasharray:5 4}.net line.red{stroke:#c00;stroke-width:2.5}.net circle{fill:#fff;stroke:#335;stroke-width:2}.net circle.red{stroke:#c00;fill:#fdd}.net circle.other{stroke:#999;stroke-dasharray:3 3}.net text{font-size:11px;text-anchor:middle}.warn{color:#a15c00}
table{border-collapse:collapse;font-size:13px;margin:6px 0}
td,th{border:1px solid #ddd;padding:3px 7px;text-align:left}th{background:#f5f5f5}
details.finding{margin:4px 0;padding:4px 8px;border-left:4px solid #999;font-size:13px}
details.finding.error{border-color:#d62728}details.finding.warning{border-color:#ff7f0e}
details.finding.info{border-color:#1f77b4}.why{color:#555}
.plot{width:100%;min-height:260px}.pair{display:flex;gap:8px}.half{width:50%}
nav a{margin-right:10px;font-size:13px}
"""

LOADER = """
(async function(){
  function unpack7(text) {  // encode.text7: 7 bits per character, U+0100+v for NUL, CR, '<'
    const out = new Uint8Array(Math.floor(text.length * 7 / 8));
    let acc = 0, bits = 0, j = 0;
    for (let i = 0; i < text.length; i++) {
      acc = ((acc << 7) | (text.charCodeAt(i) & 0x7f)) & 0x3fff;
      bits += 7;
      if (bits >= 8) { bits -= 8; out[j++] = acc >> bits; }
    }
    return out;
  }
  async function inflate(id) {  // encode.gzip7
    const stream = new Blob([unpack7(document.getElementById(id).textContent)]).stream()
      .pipeThrough(new DecompressionStream('gzip'));
    return await new Response(stream).arrayBuffer();
  }
  const s = document.createElement('script');
  s.textContent = new TextDecoder().decode(await inflate('plotlyjs'));
  document.head.appendChild(s);
  const buf = await inflate('figures');  // encode.Blob
  const n = new DataView(buf).getUint32(0, true);
  const base = Math.ceil((4 + n) / 8) * 8;
  const views = {2: Int16Array, 4: Int32Array, 8: Float64Array};
  function values(q) {
    const [at, count, size, form, first, e] = q;
    const ints = new views[size](buf, base + at, count);
    if (form === 2) return ints;
    const out = new Float64Array(count);
    const div = e < 0 ? 10 ** -e : 0, mul = 10 ** e;
    let k = first;
    for (let i = 0; i < count; i++) {
      k = form === 1 ? k + ints[i] : first + ints[i];
      out[i] = div ? k / div : k * mul;
    }
    return out;
  }
  const figs = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n)),
    (key, v) => (v && v.q && !Array.isArray(v) ? values(v.q) : v));
  const config = {responsive: true, displaylogo: false, displayModeBar: 'hover',
    modeBarButtonsToRemove: ['select2d', 'lasso2d', 'zoomIn2d', 'zoomOut2d', 'autoScale2d']};
  for (const [id, fig] of figs) {
    await Plotly.newPlot(document.getElementById(id), fig.data, fig.layout, config);
  }
  document.body.dataset.ready = 'yes';
})();
"""


@functools.lru_cache(maxsize=1)
def plotly_js_packed() -> str:
    """plotly's bundled plotly.js as `encode.gzip7` text (built once per process)."""
    from plotly.offline import get_plotlyjs

    return gzip7(get_plotlyjs().encode())


# the links above the sections: (section, its element's id, label), for those it has
NAV = (
    ("findings", "findings", "Findings"),
    ("buses", "buses", "Buses"),
    ("differences", "differences", "Differences"),
    ("nodes", "nodes", "Nodes"),
    ("boot", "boot", "Boot"),
    ("lss", "lss", "LSS"),
    ("sdo", "sdo", "SDO"),
    ("emcy", "emcy", "EMCY"),
    ("pdos", "pdo", "PDO"),
    ("network", "network", "Network"),
    ("sync_latency", "sync", "SYNC"),
    ("signals", "signals", "Signals"),
    ("drive_states", "drive", "Drive states"),
)


def _packed(text: str) -> Markup:
    """Script text of our own encoding (`encode.text7`: gzip as 7-bit characters, never
    a '<', so it cannot close its element), passed to the template as it is: escaping
    would change it (`&`, quotes) where the loader reads it raw."""
    if "<" in text:
        raise ValueError("packed script text with a '<'")
    return Markup(text)


def render(sink) -> str:
    """The whole page for a finished ReportSink."""
    run = sink.run
    sink.t0 = run.t0 if run.t0 is not None else (sink.t_first or 0.0)
    checker = run.checker
    sink.rules = checker.rules if checker is not None else []
    figs = Figures()
    sections = [(f.__name__, f(sink, figs)) for f in SECTIONS]
    sections = [(kind, data) for kind, data in sections if data is not None]
    present = {kind for kind, _ in sections}
    return templates.page().render(
        title=sink.title or f"cananalyze report: {run.name}",
        name=str(run.name),
        version=__version__,
        when=datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"),
        nav=[(anchor, label) for kind, anchor, label in NAV if kind in present],
        sections=sections,
        css=Markup(CSS),  # constants of this module
        loader=Markup(LOADER),
        plotly_js=_packed(plotly_js_packed()),
        figures=_packed(Blob().pack(figs.items)),
    )
