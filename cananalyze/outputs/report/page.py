"""The page around the sections: styles, the embedded plotly.js and the loader.

plotly.js is 4.8 MB as text; the page carries it gzip-compressed (1.47 MB, 1.72 MB as
`encode.text7`) and the browser's own DecompressionStream unpacks it, so the file
stays small and needs no network. The plots' figures wait in one more such element
(`encode.Blob`: JSON and the arrays' integers) until plotly is loaded;
`document.body.dataset.ready` is set once all are drawn (the browser test waits for it).
"""

from __future__ import annotations

import functools
import html
from datetime import UTC, datetime

from cananalyze.core.version import __version__
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
.small{font-size:12px;color:#666}.warn{color:#a15c00}
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


def render(sink) -> str:
    """The whole page for a finished ReportSink."""
    run = sink.run
    sink.t0 = run.t0 if run.t0 is not None else (sink.t_first or 0.0)
    checker = run.checker
    sink.rules = checker.rules if checker is not None else []
    figs = Figures()
    body = "".join(section(sink, figs) for section in SECTIONS)
    data = f'<script type="text/plain" id="figures">{Blob().pack(figs.items)}</script>'
    title = sink.title or f"cananalyze report: {run.name}"
    when = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    nav = "".join(
        f'<a href="#{a}">{t}</a>'
        for a, t in (
            ("findings", "Findings"),
            ("buses", "Buses"),
            ("nodes", "Nodes"),
            ("sdo", "SDO"),
            ("emcy", "EMCY"),
            ("pdo", "PDO"),
            ("signals", "Signals"),
            ("drive", "Drive states"),
        )
        if f'id="{a}"' in body
    )
    esc = html.escape
    return (
        "<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8>"
        f"<title>{esc(title)}</title><style>{CSS}</style>"
        f'<script type="text/plain" id="plotlyjs">{plotly_js_packed()}</script>'
        f"</head><body><h1>{esc(title)}</h1>"
        f"<p class=small>{esc(str(run.name))} · cananalyze {esc(__version__)} · {when}</p>"
        f"<nav>{nav}</nav>{body}{data}<script>{LOADER}</script></body></html>\n"
    )
