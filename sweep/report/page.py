"""The report page: :func:`build_report` renders a campaign's results as one self-contained
HTML text (bokeh's JavaScript inlined from ``bokeh.resources.INLINE``, every image a data
URI: it opens from the file, without a server or a network, and references nothing outside
itself), through a Jinja2 template (autoescaped); :func:`write_report` writes it to
``results/<name>/report.html`` atomically."""

from __future__ import annotations

import datetime as _dt
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..files import atomic_write_text

if TYPE_CHECKING:
    from ..outputs.tables import CampaignResults

REPORT = "report.html"

TEMPLATE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{{ c.name }}: campaign report</title>
<style>
body { font-family: sans-serif; margin: 1.5em auto; max-width: 1250px; color: #222; }
h1 { margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ccc; margin-top: 1.6em; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 2px 8px; text-align: left; vertical-align: top; }
th { background: #f0f0f0; }
.question { font-size: 1.15em; font-style: italic; }
.figure img { max-width: 100%; border: 1px solid #eee; }
pre { background: #f6f6f6; padding: 0.7em; overflow-x: auto; font-size: 0.85em; }
.note { color: #666; font-size: 0.9em; }
.scroll { max-width: 100%; overflow-x: auto; }
td { overflow-wrap: anywhere; }
</style>
{{ bokeh_resources | safe }}
</head>
<body>
<h1>Campaign {{ c.name }}</h1>
<p class="question" id="question">{{ c.description or "(the campaign has no description)" }}</p>
<table id="summary">
{% for axis, values in c.axes %}<tr><th>axis {{ axis }}</th><td>{{ values }}</td></tr>
{% endfor %}<tr><th>seeds</th><td>{{ c.seeds }}</td></tr>
<tr><th>runs</th><td>{{ c.counts.runs }}: {{ c.counts.done }} done, {{ c.counts.failed }} failed,
{{ c.counts.pending }} pending</td></tr>
{% if c.reused %}<tr><th>reused</th><td id="reused">{{ c.reused }}</td></tr>
{% endif %}</table>
<p class="note">Written {{ created }} from {{ folder }}.</p>

<h2 id="phase-diagram">Phase diagram</h2>
{% if plot_div %}<p class="note">Hover over a point for its parameters and the seed values of
the main observables; click it for one of its runs (last snapshot and σ²_S(t)).</p>
{{ plot_div | safe }}{% else %}<p>No phase diagram yet.</p>{% endif %}
{% for note in plot_notes %}<p class="note">{{ note }}</p>{% endfor %}

{% if c.product_failures %}<h2 id="product-failures">Products that failed</h2>
<p>These fits and figures failed when they were last produced ({{ failed_file }});
nematic figures draws them again.</p>
<table class="product-failures"><tr><th>product</th><th>why</th></tr>
{% for product, why in c.product_failures %}<tr><td>{{ product }}</td><td>{{ why }}</td></tr>
{% endfor %}</table>{% endif %}

<h2 id="figures">Figures</h2>
{% for name, uri in c.figures %}<div class="figure"><h3>{{ name }}</h3>
<img alt="{{ name }}" src="{{ uri }}"></div>
{% else %}<p>No figures (nematic figures draws them).</p>{% endfor %}

<h2 id="fits">Fits</h2>
{% for t in c.fits %}<h3>{{ t.title }}</h3>
<div class="scroll"><table class="fit"><tr>{% for h in t.columns %}<th>{{ h }}</th>
{% endfor %}</tr>
{% for row in t.rows %}<tr>{% for v in row %}<td>{{ v }}</td>{% endfor %}</tr>
{% endfor %}</table></div>{% if t.note %}<p class="note">{{ t.note }}</p>{% endif %}
{% else %}<p>No fits (fits.nc is absent or empty).</p>{% endfor %}

<h2 id="failures">Failures</h2>
{% for g in c.failures %}<h3 class="failure-reason">{{ g.reason }}: {{ g.count }} run(s)</h3>
<p>{{ g.detail }}{% if g.t_failed != "-" %} (the first at t = {{ g.t_failed }}){% endif %};
its record, with the traceback: {{ g.record }}</p>
<table><tr><th>swept values</th><th>seed</th><th>run</th></tr>
{% for where, seed, rid in g.runs %}
<tr><td>{{ where }}</td><td>{{ seed }}</td><td>{{ rid }}</td></tr>
{% endfor %}</table>{% if g.more %}<p class="note">and {{ g.more }} more</p>{% endif %}
{% else %}<p>No run failed.</p>{% endfor %}

{% if c.refine %}<h2 id="refine">Refinement rounds</h2>
<p>{% if c.refine.finished %}Finished: {{ c.refine.stop }}{% else %}In progress{% endif %};
{{ c.refine.rounds | length }} round(s), at most {{ c.refine.run_bound }} runs.</p>
{% for r in c.refine.rounds %}
<h3 class="refine-round">round {{ r.number }}: {{ r.n_runs }} run(s)</h3>
<table><tr><th>point</th><th>seeds</th><th>why</th><th>state</th></tr>
{% for p in r.points %}<tr><td>{{ p.where }}</td><td>{{ p.seeds | join(", ") }}</td>
<td>{{ p.why }}</td><td>{{ p.states | join(", ") }}</td></tr>
{% endfor %}</table>{% endfor %}{% endif %}

{% if c.verification %}<h2 id="verification">Verification</h2>
<p class="verify-summary">{{ c.verification.summary }}</p>
<p class="note">Each sampled point rerun with seeds {{ c.verification.seeds }} under every
variant; converged: every compared observable changes by less than
{{ c.verification.threshold }} (relative; absolute for cos2theta) and the pattern class is
kept (results/NAME/verify.nc).</p>
<div class="scroll"><table class="verify"><tr><th>point</th><th>why</th><th>variant</th>
<th>verdict</th><th>changes</th></tr>
{% for r in c.verification.rows %}<tr><td>{{ r.point }}</td><td>{{ r.why }}</td>
<td>{{ r.variant }}</td><td>{{ r.verdict }}</td><td>{{ r.changes }}</td></tr>
{% endfor %}</table></div>
{% if c.verification.transitions %}<table class="verify-transitions"><tr><th>transition</th>
<th>variant</th><th>recomputed</th></tr>
{% for r in c.verification.transitions %}<tr><td>{{ r.transition }}</td><td>{{ r.variant }}</td>
<td>{{ r.where }}</td></tr>{% endfor %}</table>{% endif %}{% endif %}

<h2 id="cost">Cost</h2>
{% if c.cost.n %}<p>{{ "%.3g" | format(c.cost.cpu_hours) }} CPU-hours: the sum of the wall
times of {{ c.cost.n }} run(s) ({{ "%.3g" | format(c.cost.total_seconds) }} s; one core each),
median {{ "%.3g" | format(c.cost.median) }} s, from {{ "%.3g" | format(c.cost.min) }} s to
{{ "%.3g" | format(c.cost.max) }} s.</p>
<img alt="run time histogram" src="{{ c.cost.histogram }}">
{% else %}<p>No run has a recorded wall time.</p>{% endif %}

<h2 id="provenance">Provenance</h2>
<table>{% for k, v in c.provenance %}<tr><th>{{ k }}</th><td>{{ v }}</td></tr>{% endfor %}
</table>
<h3>The campaign file (campaign.yaml)</h3>
<pre id="campaign-yaml">{{ c.campaign_yaml }}</pre>
{{ plot_script | safe }}
</body>
</html>
"""


def inline_resources(layout: Any) -> str:
    """The CSS and JavaScript of the bokeh bundles ``layout`` uses, inlined from
    ``bokeh.resources.INLINE`` (no server, no CDN): bokeh itself, its widgets if used, and
    its MathJax bundle (``bokeh-mathjax``) if a label holds TeX (``$$...$$``), so that such
    math renders offline too. Nothing the page runs fetches anything: bokeh's own code holds
    the address of MathJax on a CDN (``.../npm/mathjax@3/es5/tex-svg.js``) as a string, for a
    provider it does not use (its default is the bundled one)."""
    from bokeh.embed.bundle import bundle_for_objs_and_resources
    from bokeh.resources import INLINE

    js, css = bundle_for_objs_and_resources([layout], INLINE)
    return str(css) + str(js)


def build_report(opened: CampaignResults) -> str:
    """The report of the campaign ``opened`` (:func:`nematic_solids.sweep.open_campaign`) as HTML
    text."""
    import jinja2
    from bokeh.embed import components

    from ..figures.failed import FAILED_PRODUCTS
    from ..outputs.aggregate import phase_dataset
    from ..outputs.status import campaign_status
    from .content import gather
    from .phase_plot import phase_layout

    store = opened.store
    expansion = opened.expansion()
    status = campaign_status(expansion, store)
    records = store.scan(save=False)
    phase = phase_dataset(expansion, store, records)
    content = gather(opened, phase, status, records)
    layout, _, notes = phase_layout(phase, store.runs_dir)
    script, div, resources = "", "", ""
    if layout is not None:
        script, div = components(layout)
        resources = inline_resources(layout)
    env = jinja2.Environment(autoescape=True, undefined=jinja2.StrictUndefined)
    created = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    return env.from_string(TEMPLATE).render(
        c=content,
        bokeh_resources=resources,
        plot_div=div,
        plot_script=script,
        plot_notes=notes,
        created=created,
        folder=str(store.root),
        failed_file=FAILED_PRODUCTS,
    )


def write_report(opened: CampaignResults, path: Path | None = None) -> Path:
    """Write the report (default ``results/<name>/report.html``) atomically; return its
    path."""
    target = Path(path) if path is not None else opened.store.root / REPORT
    text = build_report(opened)
    target.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(target, text)
    return target
