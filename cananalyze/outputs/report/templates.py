"""The report's HTML as Jinja2 templates, escaped by construction.

Autoescape is on and undefined names raise (`StrictUndefined`): every value the
templates are given (channel, node, signal and file names, titles, finding texts) is
plain text and comes out as text, in element content and in attribute values alike.
The sections (`sections.py`) compute plain data; only the page's own constants and its
packed script text are passed as `Markup` (`page.py` says why each is trusted).

The templates are strings here, not files, so an installed wheel needs no package
data. The page is one line, as it was built before: each template's line breaks and
the indentation after them are removed when it is loaded (`_compact`), so a line may
only end where no white space belongs (between tags, at a `{% ... %}` tag); a space
that matters stays inside its line.
"""

from __future__ import annotations

import re

from jinja2 import DictLoader, Environment, StrictUndefined, Template


def _compact(source: str) -> str:
    """The template without its line breaks and the indentation that follows them."""
    return re.sub(r"\n\s*", "", source)


PAGE = r"""
<!DOCTYPE html>{{ "\n" }}<html lang=en><head><meta charset=utf-8>
<title>{{ title }}</title><style>{{ css }}</style>
<script type="text/plain" id="plotlyjs">{{ plotly_js }}</script>
</head><body><h1>{{ title }}</h1>
<p class=small>{{ name }} · cananalyze {{ version }} · {{ when }}</p>
<nav>{% for anchor, label in nav %}<a href="#{{ anchor }}">{{ label }}</a>{% endfor %}</nav>
{% import "sections.html" as parts %}
{% for kind, data in sections %}{{ parts[kind](data) }}{% endfor %}
<script type="text/plain" id="figures">{{ figures }}</script>
<script>{{ loader }}</script></body></html>{{ "\n" }}
"""

# one macro per section, named as its function in sections.py, given that function's data
SECTIONS = """
{% macro plot(p) %}<div class="{{ p.cls }}" id="{{ p.id }}"></div>{% endmacro %}

{% macro table(head, rows, cls="") %}
  <table class="{{ cls }}"><thead><tr>
  {% for h in head %}<th>{{ h }}</th>{% endfor %}
  </tr></thead><tbody>
  {% for row in rows %}<tr>{% for cell in row %}<td>{{ cell }}</td>{% endfor %}</tr>{% endfor %}
  </tbody></table>
{% endmacro %}

{% macro verdict(s) %}
  <section id="verdict">
  <div class="verdict {{ 'pass' if s.ok else 'fail' }}" id="verdict-banner">
  <b>{{ 'PASS' if s.ok else 'FAIL' }}</b> {{ s.text }}</div>
  <p class=small>Rules: {{ s.rules or 'none' }}</p>
  {% if s.skipped %}<p class=warn>{{ s.skipped }} unreadable lines/records skipped</p>{% endif %}
  {% if s.load %}{{ plot(s.load) }}{% endif %}
  </section>
{% endmacro %}

{% macro buses(s) %}
  <section id="buses"><h2>Buses</h2>
  {{ table(["channel", "frames", "error frames", "mean load", "peak load (100 ms)"], s.rows) }}
  {% if s.nodes %}<h3>Bus load per node</h3>
  {{ table(["node", "frames it sent", "mean load"], s.nodes) }}{% endif %}
  {% if s.bursts %}<h3>Longest burst</h3>
  {{ table(["channel", "frames back to back", "from", "length"], s.bursts) }}{% endif %}
  {% if not s.bitrate %}<p class=small>Give --bitrate for the load in percent.</p>{% endif %}
  <p class=small>Nominal bits without stuff bits: a lower bound.</p></section>
{% endmacro %}

{% macro findings(s) %}
  {% if not s.groups %}
    <section id="findings"><h2>Findings</h2><p>No findings.</p></section>
  {% else %}
    <section id="findings"><h2>Findings by node and rule</h2>
    {% for g in s.groups %}
      <details class="finding {{ g.severity }}"><summary>
      <b>{{ g.who }}</b> · {{ g.rule }} · {{ g.count }} finding(s), first at {{ g.first_at }}:
      {{ " " }}{{ g.message }} (measured {{ g.measured }}, expected {{ g.expected }})
      </summary>
      {% for why in g.whys %}<p class=why>{{ why }}</p>{% endfor %}
      <ul>
      {% for line in g.lines %}<li>{{ line }}</li>{% endfor %}
      {% if g.more %}
        <li>... and {{ g.more }} more (every one in <code>check --json</code> and JUnit)</li>
      {% endif %}
      </ul></details>
    {% endfor %}
    </section>
  {% endif %}
{% endmacro %}

{% macro differences(s) %}
  <section id="differences"><h2>Differences</h2>
  <p>Compared with {{ s.reference }}
  {{ " (a DCF: configuration only)" if s.kind == "dcf" else " (another log)" }},
  {{ " " }}as <code>cananalyze diff</code> compares:
  {% if s.rows %}{{ " " }}{{ s.rows | length }} difference(s).{% else %}
  {{ " " }}no differences.{% endif %}</p>
  {% if s.rows %}{{ table(["node", "section", "item", "this log", "B"], s.rows) }}{% endif %}
  {% if s.note %}<p class=small>{{ s.note }}</p>{% endif %}
  </section>
{% endmacro %}

{% macro nodes(s) %}
  <section id="nodes"><h2>Nodes</h2>
  {% if s.timeline %}{{ plot(s.timeline) }}{% endif %}
  {% if s.states_dropped %}
    <p class=warn>{{ s.states_dropped }} more NMT state changes not drawn</p>
  {% endif %}
  {% for n in s.nodes %}
    <div class="node" id="{{ n.id }}"><h3>{{ n.name }}: {{ n.device }}</h3>
    <p>Identified by: {{ n.how }}{% if n.ident %}; {{ n.ident }}{% endif %}.
    {{ " " }}{{ n.frames }} frames; last NMT state {{ n.last_state }}.</p>
    {% for p in n.periods %}
      <p>{{ p.kind }} period: n={{ p.count }} min {{ p.min }} median {{ p.median }}
      {{ " " }}mean {{ p.mean }} p99 {{ p.p99 }} max {{ p.max }} jitter (std) {{ p.std }} ms;
      {{ " " }}{{ p.configured }}</p>
      <div class=pair>{{ plot(p.plot) }}{{ plot(p.histogram) }}</div>
    {% endfor %}
    </div>
  {% endfor %}
  </section>
{% endmacro %}

{% macro boot(s) %}
  <section id="boot"><h2>Boot-up (CiA 302-2)</h2>
  {% for b in s.stories %}
    <div class="boot" id="{{ b.id }}"><h3>{{ b.name }}: boot-up {{ b.life }}{{ b.at }}</h3>
    <p>Result: <b>{{ b.result }}</b>; stopped at: {{ b.stopped_at }};
    {{ " " }}CiA 302-2 error status: {{ b.status }}; configuration: {{ b.writes }}.</p>
    {{ table(["time", "step", "result", "detail"], b.steps) }}
    <p>{{ b.verdict }}</p></div>
  {% endfor %}
  <p class=small>Each node's boot as a CiA 302-2 master runs it, from the log; the identity
  {{ " " }}read is compared with the device declared (--device, --eds, the network file).</p>
  </section>
{% endmacro %}

{% macro lss(s) %}
  <section id="lss"><h2>LSS (CiA 305)</h2>
  {% if s.assigned %}
    <h3>Node-IDs assigned</h3>{{ table(s.assigned_head, s.assigned) }}
  {% else %}<p>No node-ID was assigned.</p>{% endif %}
  <h3>Steps</h3>{{ table(s.steps_head, s.steps) }}
  </section>
{% endmacro %}

{% macro sdo(s) %}
  <section id="sdo"><h2>SDO transfers</h2>
  {{ table(["node", "transfers", "aborts", "min ms", "median ms", "p99 ms", "max ms"], s.rows) }}
  {% if s.latency %}{{ plot(s.latency) }}{% endif %}
  {% if s.aborts %}
    <h3>Aborts and timeouts</h3>
    {{ table(["time", "node", "direction", "object", "name", "code", "text"], s.aborts) }}
  {% endif %}
  </section>
{% endmacro %}

{% macro emcy(s) %}
  <section id="emcy"><h2>EMCY</h2>
  {{ table(["time", "node", "code", "register", "meaning", "active for"], s.rows) }}
  {% if s.more %}<p class=warn>{{ s.more }} more EMCYs not listed</p>{% endif %}
  </section>
{% endmacro %}

{% macro pdos(s) %}
  <section id="pdo"><h2>PDO rates</h2>
  {{ table(["COB-ID", "node", "PDO", "frames", "rate Hz", "min gap ms", "median gap ms",
            "max gap ms", "transmission type", "event timer", "inhibit time", "findings"],
           s.rows) }}
  <p class=small>Configured values as known at the end of the log, with where each comes from:
  {{ " " }}log (an SDO write or read), file (network or rules file, --device/--eds)
  {{ " " }}or profile (EDS/DCF).</p></section>
{% endmacro %}

{% macro network(s) %}
  <section id="network"><h2>Network</h2>
  {% for b in s.buses %}
    {% if b.label %}<h3>{{ b.label }}</h3>{% endif %}
    <svg class=net width="{{ b.size }}" height="{{ b.size }}" viewBox="0 0 {{ b.size }} {{ b.size }}" role=img aria-label="who produces and consumes which PDO, who watches whose heartbeat">
    <defs><marker id="arrow{{ loop.index }}" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="7" markerHeight="7" orient="auto"><path d="M0 0L10 5L0 10z" fill="#557"/></marker></defs>
    {% set arrow = "url(#arrow" ~ loop.index ~ ")" %}
    {% for e in b.edges %}
      <line x1="{{ e.x1 }}" y1="{{ e.y1 }}" x2="{{ e.x2 }}" y2="{{ e.y2 }}" class="{{ e.cls }}" marker-end="{{ arrow }}"/>
      <text x="{{ e.lx }}" y="{{ e.ly }}">{{ e.label }}</text>
    {% endfor %}
    {% for n in b.nodes %}
      <circle cx="{{ n.x }}" cy="{{ n.y }}" r="18" class="{{ n.cls }}"/>
      <text x="{{ n.x }}" y="{{ n.y + 4 }}">{{ n.label }}</text>
    {% endfor %}
    </svg>
  {% endfor %}
  {{ table(s.head, s.rows) }}
  <p class=small>The configuration in force at the end of the log (SDO writes in the log, the
  {{ " " }}network file, the profiles): solid arrows from a PDO's producer to each consumer,
  {{ " " }}dashed ones from a heartbeat producer to the node that watches it (0x1016); "other":
  {{ " " }}a producer or consumer no configuration names (often the master); red:
  {{ " " }}what the consistency rule found contradictory.</p>
  </section>
{% endmacro %}

{% macro sync_latency(s) %}
  <section id="sync"><h2>Synchronous PDOs after SYNC</h2>
  {{ table(["COB-ID", "node", "PDO", "type", "frames", "min ms", "median ms", "p99 ms",
            "max ms", "jitter ms", "window 0x1007 ms", "margin ms"], s.rows) }}
  {% for p in s.plots %}{{ plot(p) }}{% endfor %}
  <p class=small>Each synchronous PDO (transmission type 0-240) after the SYNC before it; the
  {{ " " }}window is the one in force at its last frame (the pdo_sync rule judges each).</p>
  </section>
{% endmacro %}

{% macro signals(s) %}
  <section id="signals"><h2>Signals per PDO</h2>
  {% for p in s.plots %}{{ plot(p) }}{% endfor %}
  {% if s.dropped %}<p class=warn>{{ s.dropped }} more signals not plotted</p>{% endif %}
  </section>
{% endmacro %}

{% macro drive_states(s) %}
  <section id="drive"><h2>Drive states (CiA 402)</h2>{{ plot(s.plot) }}</section>
{% endmacro %}
"""

ENV = Environment(
    loader=DictLoader({"page.html": _compact(PAGE), "sections.html": _compact(SECTIONS)}),
    autoescape=True,
    undefined=StrictUndefined,
)


def page() -> Template:
    return ENV.get_template("page.html")
