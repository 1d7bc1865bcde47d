"""The page around the sections: styles, the embedded plotly.js and the loader.

plotly.js is 4.8 MB as text; the page carries it gzip-compressed (1.5 MB as base64)
and the browser's own DecompressionStream unpacks it, so the file stays small and
needs no network. Each plot's JSON waits in a <script type="application/json">
until plotly is loaded; `document.body.dataset.ready` is set once all are drawn
(the browser test waits for it).
"""

from __future__ import annotations

import base64
import functools
import gzip
import html
from datetime import UTC, datetime

from ... import __version__
from .sections import SECTIONS, Figures

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
  const b64 = document.getElementById('plotlyjs').textContent;
  const bytes = Uint8Array.from(atob(b64), c => c.charCodeAt(0));
  const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('gzip'));
  const code = await new Response(stream).text();
  const s = document.createElement('script');
  s.textContent = code;
  document.head.appendChild(s);
  const config = {responsive: true, displaylogo: false};
  for (const div of document.querySelectorAll('div.plot')) {
    const fig = JSON.parse(document.getElementById(div.id + '-data').textContent);
    await Plotly.newPlot(div, fig.data, fig.layout, config);
  }
  document.body.dataset.ready = 'yes';
})();
"""


@functools.lru_cache(maxsize=1)
def plotly_js_gzip_b64() -> str:
    """plotly's bundled plotly.js, gzip-compressed and base64-encoded (built once)."""
    from plotly.offline import get_plotlyjs

    packed = gzip.compress(get_plotlyjs().encode(), compresslevel=9, mtime=0)
    return base64.b64encode(packed).decode("ascii")


def _script_json(text: str) -> str:
    """JSON safe inside <script>: no '</' can close the element early."""
    return text.replace("</", "<\\/")


def render(sink) -> str:
    """The whole page for a finished ReportSink."""
    run = sink.run
    sink.t0 = run.t0 if run.t0 is not None else (sink.t_first or 0.0)
    checker = run.checker
    sink.rules = checker.rules if checker is not None else []
    figs = Figures()
    body = "".join(section(sink, figs) for section in SECTIONS)
    data = "".join(
        f'<script type="application/json" id="{pid}-data">{_script_json(j)}</script>'
        for pid, j in figs.items
    )
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
        f'<script type="text/plain" id="plotlyjs">{plotly_js_gzip_b64()}</script>'
        f"</head><body><h1>{esc(title)}</h1>"
        f"<p class=small>{esc(str(run.name))} · cananalyze {esc(__version__)} · {when}</p>"
        f"<nav>{nav}</nav>{body}{data}<script>{LOADER}</script></body></html>\n"
    )
