// The nematic service's dashboard: plain JavaScript and SVG (no library, no network but the
// service's own API). Listens to /api/events (server-sent events) and fetches what changed.
"use strict";
(function () {
  const body = document.body;
  const kind = body.dataset.page;
  const name = body.dataset.campaign;
  const csrf = document.querySelector('meta[name="nematic-csrf"]').content;
  const main = document.getElementById("main");
  const live = document.getElementById("live");
  const SVGNS = "http://www.w3.org/2000/svg";
  let seq = 0;
  let selected = null; // the clicked point's key
  let shownRun = null;
  let busy = false, again = false;

  const esc = (s) => String(s ?? "").replace(/[&<>"']/g,
    (c) => ({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;"}[c]));
  const fmt = (x) => (x === null || x === undefined) ? "" : typeof x !== "number" ? String(x) :
    Number.isInteger(x) && Math.abs(x) < 1e6 ? String(x) :
    x !== 0 && (Math.abs(x) < 1e-3 || Math.abs(x) >= 1e5) ? x.toExponential(3) :
    String(Number(x.toPrecision(4)));
  const secs = (s) => s === null || s === undefined ? "?" : s < 1 ? `${s.toPrecision(2)} s` :
    s < 120 ? `${s.toFixed(1)} s` :
    s < 7200 ? `${(s / 60).toFixed(1)} min` : `${(s / 3600).toFixed(2)} h`;
  const where = (coords) => Object.entries(coords).map(([k, v]) => `${k}=${fmt(v)}`).join(", ");

  async function api(path, options) {
    const r = await fetch(path, Object.assign({credentials: "same-origin"}, options || {}));
    if (!r.ok) { throw new Error(`${path}: ${r.status} ${(await r.text()).slice(0, 200)}`); }
    return r.json();
  }
  function post(path, data) {
    return api(path, {method: "POST", headers: {"Content-Type": "application/json",
      "X-Nematic-CSRF": csrf}, body: JSON.stringify(data || {})});
  }

  function bar(ok, failed, total) {
    const w = (n) => total ? (100 * n / total).toFixed(1) : 0;
    return `<span class="bar" title="${ok} ok, ${failed} failed of ${total}">` +
      `<span class="ok" style="left:0;width:${w(ok)}%"></span>` +
      `<span class="failed" style="left:${w(ok)}%;width:${w(failed)}%"></span></span> ` +
      `${ok + failed}/${total}`;
  }

  // ------------------------------------------------------------------ all campaigns
  async function drawIndex() {
    const data = await api("/api/campaigns");
    seq = data.seq;
    const rows = data.campaigns.map((c) => {
      const q = c.queue || {};
      const p = c.progress;
      const progress = p ? bar(p.done, p.failed, p.total) + ` <span class="muted">${esc(p.phase)}</span>` : "";
      const can = q.state === "queued" || q.state === "running";
      return `<tr data-campaign="${esc(c.name)}"><td><a href="/campaigns/${encodeURIComponent(c.name)}">` +
        `${esc(c.name)}</a></td><td class="state ${esc(c.state)}">${esc(c.state)}</td>` +
        `<td>${progress}</td><td>${esc(q.priority ?? "")}</td><td>${esc(q.submitted ?? "")}</td>` +
        `<td>${esc(q.message ?? "")}</td><td>${can ? `<button data-cancel="${q.id}">cancel</button>` : ""}</td></tr>`;
    }).join("");
    main.innerHTML = `<h1>Campaigns</h1><table id="campaigns"><tr><th>campaign</th><th>state</th>` +
      `<th>progress</th><th>priority</th><th>submitted</th><th>message</th><th></th></tr>${rows}</table>` +
      `<p class="muted">Queue order: a campaign the service was running when it stopped, then ` +
      `the highest priority, then the earliest submission. Submit with <code>nematic submit FILE</code>.</p>`;
    for (const b of main.querySelectorAll("button[data-cancel]")) {
      b.onclick = async () => { b.disabled = true; await post(`/api/queue/${b.dataset.cancel}/cancel`); refresh(); };
    }
  }

  // ------------------------------------------------------------------ one campaign
  const VIRIDIS = ["#440154", "#482878", "#3e4989", "#31688e", "#26828e", "#1f9e89",
    "#35b779", "#6ece58", "#b5de2b", "#fde725"];
  function colour(t) {
    if (!Number.isFinite(t)) { return "#bbb"; }
    return VIRIDIS[Math.max(0, Math.min(9, Math.floor(t * 10)))];
  }
  function scale(values, lo, hi) {
    const xs = values.filter((v) => typeof v === "number" && Number.isFinite(v));
    if (!xs.length) { return {f: () => (lo + hi) / 2, log: false, ticks: []}; }
    let min = Math.min(...xs), max = Math.max(...xs);
    const log = min > 0 && max / min >= 10;
    const t = (v) => log ? Math.log10(v) : v;
    let a = t(min), b = t(max);
    if (a === b) { a -= 0.5; b += 0.5; }
    const pad = (b - a) * 0.06;
    a -= pad; b += pad;
    const f = (v) => lo + (t(v) - a) / (b - a) * (hi - lo);
    const uniq = [...new Set(xs)].sort((p, q) => p - q);
    const ticks = uniq.length <= 8 ? uniq : [min, max];
    return {f, log, ticks};
  }
  function el(tag, attrs, parent) {
    const e = document.createElementNS(SVGNS, tag);
    for (const [k, v] of Object.entries(attrs)) { e.setAttribute(k, v); }
    if (parent) { parent.appendChild(e); }
    return e;
  }
  // the dims beyond the diagram's two: one selector each (the slice shown)
  const slice = {};
  function sliceOf(data) {
    const extra = data.dims.slice(2);
    for (const d of extra) {
      const values = [...new Set(data.points.map((p) => p.coords[d]))].sort((a, b) => a < b ? -1 : a > b ? 1 : 0);
      if (!values.some((v) => v === slice[d])) { slice[d] = values[0]; }
    }
    return extra;
  }
  function selectors(data) {
    const extra = sliceOf(data);
    if (!extra.length) { return ""; }
    return `<p id="slice">` + extra.map((d) => {
      const values = [...new Set(data.points.map((p) => p.coords[d]))].sort((a, b) => a < b ? -1 : a > b ? 1 : 0);
      return `<label>${esc(d)} <select data-dim="${esc(d)}">` + values.map((v, i) =>
        `<option value="${i}"${v === slice[d] ? " selected" : ""}>${esc(fmt(v))}</option>`).join("") + "</select></label> ";
    }).join("") + `<span class="muted">(the diagram shows one value of each other axis)</span></p>`;
  }
  const GLYPH = {converged: "\u2713", CHANGED: "\u2717", "not compared": "?"};
  function phaseDiagram(data) {
    const W = 580, H = 420, L = 84, R = 20, T = 24, B = 46;
    const svg = el("svg", {width: W, height: H, id: "phase", role: "img"});
    const dims = data.dims;
    const extra = sliceOf(data);
    const pts = data.points.filter((p) => extra.every((d) => p.coords[d] === slice[d]));
    const xdim = dims[0], ydim = dims.length > 1 ? dims[1] : null;
    const xs = scale(pts.map((p) => p.coords[xdim]), L, W - R);
    const means = data.points.map((p) => p.mean).filter(Number.isFinite);
    const cmin = Math.min(...means), cmax = Math.max(...means);
    let ys;
    if (ydim) {
      ys = scale(pts.map((p) => p.coords[ydim]), H - B, T);
    } else {
      const vals = pts.flatMap((p) => [p.mean, p.low, p.high]);
      ys = scale(vals, H - B, T);
    }
    el("line", {x1: L, x2: W - R, y1: H - B, y2: H - B, stroke: "#444"}, svg);
    el("line", {x1: L, x2: L, y1: T, y2: H - B, stroke: "#444"}, svg);
    for (const v of xs.ticks) {
      el("text", {x: xs.f(v), y: H - B + 14, "text-anchor": "middle"}, svg).textContent = fmt(v);
    }
    el("text", {x: (L + W - R) / 2, y: H - 8, "text-anchor": "middle"}, svg).textContent =
      xdim + (xs.log ? " (log)" : "");
    const ylabel = ydim ? ydim + (ys.log ? " (log)" : "") : `${data.shown} (seed mean, ${Math.round(100 * data.confidence)} % interval)`;
    el("text", {x: 14, y: (T + H - B) / 2, transform: `rotate(-90 14 ${(T + H - B) / 2})`,
      "text-anchor": "middle"}, svg).textContent = ylabel;
    const shownMeans = pts.map((p) => p.mean).filter(Number.isFinite);
    const yticks = ydim ? ys.ticks : (shownMeans.length ? [Math.min(...shownMeans), Math.max(...shownMeans)] : []);
    for (const v of yticks) {
      el("text", {x: L - 4, y: ys.f(v) + 4, "text-anchor": "end"}, svg).textContent = fmt(v);
    }
    const rounds = pts.some((p) => p.round > 0), verdicts = pts.some((p) => p.verdict);
    el("text", {x: L, y: 14}, svg).textContent = (ydim ?
      `colour: seed mean of ${data.shown} (${fmt(cmin)} to ${fmt(cmax)}); grey: no run done; red ring: failures` :
      "grey: no run done; red ring: failures") + (rounds ? "; rN: its round N (added, or seeded last)" : "") +
      (verdicts ? "; \u2713/\u2717: verified, converged/changed" : "");
    pts.forEach((p) => {
      const key = where(p.coords);
      const x = xs.f(p.coords[xdim]);
      let y;
      if (ydim) { y = ys.f(p.coords[ydim]); } else {
        y = Number.isFinite(p.mean) ? ys.f(p.mean) : H - B - 6;
        if (Number.isFinite(p.low) && Number.isFinite(p.high)) {
          el("line", {x1: x, x2: x, y1: ys.f(p.low), y2: ys.f(p.high), stroke: "#333"}, svg);
        }
      }
      const t = cmax > cmin ? (p.mean - cmin) / (cmax - cmin) : 0.5;
      const r = ydim ? 9 : 6;
      const c = el("circle", {cx: x, cy: y, r,
        fill: p.n ? (ydim ? colour(t) : "#36c") : "#ddd",
        stroke: p.failed ? "#d00" : "#555", "stroke-width": p.failed ? 2.5 : 1,
        class: "point" + (key === selected ? " selected" : ""), "data-index": p.index,
        "data-key": key}, svg);
      const title = el("title", {}, c);
      title.textContent = `${key}: ${data.shown} = ${fmt(p.mean)} [${fmt(p.low)}, ${fmt(p.high)}], ` +
        `${p.ok} ok, ${p.failed} failed, ${p.pending} pending` +
        (p.round !== undefined ? `; round ${p.round}` : "") + (p.decision ? `; seeds: ${p.decision}` : "") +
        (p.verdicts ? `; verification: ${p.verdicts.join(", ")}` : "");
      c.addEventListener("click", () => { selected = key; draw(data); });
      if (p.round > 0) {
        el("text", {x: x - r - 2, y: y - r + 2, "text-anchor": "end", class: "round",
          "data-round": p.round}, svg).textContent = `r${p.round}`;
      }
      if (p.verdict) {
        const g = el("text", {x: x + r + 1, y: y - r + 4, class: "verdict " +
          (p.verdict === "CHANGED" ? "changed" : p.verdict === "converged" ? "converged" : "open"),
          "data-verdict": p.verdict}, svg);
        g.textContent = GLYPH[p.verdict] || "?";
        el("title", {}, g).textContent = `verification: ${(p.verdicts || []).join(", ")}`;
      }
    });
    return svg;
  }

  function seriesPlot(run) {
    const W = 440, H = 260, L = 74, R = 12, T = 16, B = 36;
    const svg = el("svg", {width: W, height: H, id: "series"});
    const y = run.series.sigma2_S || Object.values(run.series)[0] || [];
    const t = run.t;
    if (!t.length || !y.length) {
      el("text", {x: 20, y: 40}, svg).textContent = "no time series stored for this run";
      return svg;
    }
    const xs = scale(t, L, W - R), ys = scale(y, H - B, T);
    el("line", {x1: L, x2: W - R, y1: H - B, y2: H - B, stroke: "#444"}, svg);
    el("line", {x1: L, x2: L, y1: T, y2: H - B, stroke: "#444"}, svg);
    const d = t.map((tv, i) => (Number.isFinite(y[i]) ? `${i ? "L" : "M"}${xs.f(tv).toFixed(1)},${ys.f(y[i]).toFixed(1)}` : "")).join("");
    el("path", {d, fill: "none", stroke: "#36c", "stroke-width": 1.5, class: "series-line"}, svg);
    el("text", {x: (L + W - R) / 2, y: H - 6, "text-anchor": "middle"}, svg).textContent = "t";
    el("text", {x: L, y: 12}, svg).textContent = "sigma2_S(t)";
    for (const v of [Math.min(...y.filter(Number.isFinite)), Math.max(...y.filter(Number.isFinite))]) {
      el("text", {x: L - 4, y: ys.f(v) + 4, "text-anchor": "end"}, svg).textContent = fmt(v);
    }
    return svg;
  }

  async function showRun(runId) {
    shownRun = runId;
    const box = document.getElementById("run");
    const run = await api(`/api/campaigns/${encodeURIComponent(name)}/runs/${encodeURIComponent(runId)}`);
    const r = run.record;
    box.innerHTML = `<h3>run ${esc(r.run_id)}</h3><p>seed ${esc(r.seed)}, ${esc(r.status)}` +
      (r.reason ? ` (${esc(r.reason)}${r.t_failed !== null && r.t_failed !== undefined ? " at t = " + fmt(r.t_failed) : ""})` : "") +
      `, wall time ${secs(r.wall_time)}</p>`;
    box.dataset.run = r.run_id;
    box.appendChild(seriesPlot(run));
  }

  async function showPoint(data, p) {
    const box = document.getElementById("point");
    if (!box) { return; }
    const runs = (await api(`/api/campaigns/${encodeURIComponent(name)}/points/${p.index}`)).runs;
    const rows = runs.map((r) => `<tr><td>${esc(r.seed)}</td><td class="state ${r.status === "ok" ? "done" : esc(r.status)}">${esc(r.status)}</td>` +
      `<td>${fmt(r.value)}</td><td>${r.status === "pending" ? "" : `<span class="run-link" data-run="${esc(r.run_id)}">${esc(r.run_id)}</span>`}</td></tr>`).join("");
    const marks = (p.round !== undefined ? `<p>round ${esc(p.round)}${p.decision ? `, seeds: ${esc(p.decision)}` : ""}</p>` : "") +
      (p.verdicts ? `<p>verification: ${esc(p.verdicts.join(", "))}</p>` : "");
    box.innerHTML = `<h3>${esc(where(p.coords))}</h3><p>${data.shown}: ${fmt(p.mean)} ` +
      `[${fmt(p.low)}, ${fmt(p.high)}] over ${p.n} seed(s)</p>${marks}<table><tr><th>seed</th><th>status</th>` +
      `<th>${data.shown}</th><th>run</th></tr>${rows}</table><div id="run"></div>`;
    for (const a of box.querySelectorAll(".run-link")) { a.onclick = () => showRun(a.dataset.run); }
    const first = runs.find((r) => r.status !== "pending");
    if (first) { showRun(shownRun && runs.some((r) => r.run_id === shownRun) ? shownRun : first.run_id); }
  }

  function draw(data) {
    const q = data.queue || {};
    const p = data.progress;
    const c = data.counts || {ok: 0, failed: 0, pending: 0};
    const est = data.estimate;
    const cost = data.cost || {cpu_seconds: 0, runs: 0};
    const estText = est ? `estimate at launch: ${secs(est.cpu_seconds[0])} CPU (${secs(est.cpu_seconds[1])} to ` +
      `${secs(est.cpu_seconds[2])}) for ${est.runs_to_do} run(s), ${secs(est.wall_seconds[0])} wall on ${est.workers} worker(s); basis: ${esc(est.basis)}` : "no estimate (not run by the service)";
    const fails = (data.failures || []).map((f) => `<tr><td><span class="run-link" data-run="${esc(f.run_id)}">${esc(f.run_id)}</span></td>` +
      `<td>${esc(where(f.coords))}</td><td>${esc(f.reason)}</td><td>${fmt(f.t_failed)}</td><td>${esc(f.detail)}</td></tr>`).join("");
    let rounds = "";
    if (data.rounds) {
      rounds = `<h2>Rounds</h2><p>${data.rounds.finished ? "finished: " + esc(data.rounds.stop) : "in progress"}</p><table>` +
        `<tr><th>round</th><th>runs</th><th>new points</th><th>points seeded</th></tr>` +
        data.rounds.rounds.map((r) => `<tr><td>${esc(r.round)}</td><td>${esc(r.n_runs)}</td><td>${esc(r.new_points ?? "")}</td><td>${esc(r.seeded_points ?? "")}</td></tr>`).join("") + "</table>";
      if (data.rounds.decisions.length) {
        rounds += `<table><tr><th>point</th><th>seeds run</th><th>decision</th><th>why</th></tr>` +
          data.rounds.decisions.map((d) => `<tr><td>${esc(where(d.coords || {}))}</td><td>${esc(d.seeds_run)}</td><td>${esc(d.decision)}</td><td>${esc(d.why)}</td></tr>`).join("") + "</table>";
      }
    }
    let verify = "";
    if (data.verification) {
      const rows = data.verification.rows || [];
      const heads = rows.length ? Object.keys(rows[0]) : [];
      verify = `<h2>Verification</h2><p>${esc(data.verification.summary)}</p>` + (rows.length ?
        `<table><tr>${heads.map((h) => `<th>${esc(h)}</th>`).join("")}</tr>` +
        rows.map((r) => `<tr>${heads.map((h) => `<td>${esc(r[h])}</td>`).join("")}</tr>`).join("") + "</table>" : "");
    }
    main.innerHTML = `<h1>${esc(data.name)} <span class="state ${esc(q.state || "done")}" id="state">${esc(q.state || "done")}</span></h1>` +
      `<p>${esc(data.description || "")}</p>` +
      `<p id="progress">${bar(c.ok, c.failed, data.total)} ${p ? `<span class="muted">${esc(p.phase)}</span>` : ""} ` +
      `<span class="muted">${esc(q.message || "")}</span></p>` +
      `<p id="cost">cost so far: ${secs(cost.cpu_seconds)} CPU over ${cost.runs} run(s); ${estText}</p>` +
      selectors(data) +
      `<div class="grid"><div class="panel" id="diagram"></div><div class="panel" id="point">` +
      `<p class="muted">Click a point to show its runs.</p></div></div>` +
      `<h2>Failures (${(data.failures || []).length})</h2>` +
      (fails ? `<table id="failures"><tr><th>run</th><th>where</th><th>reason</th><th>t</th><th>detail</th></tr>${fails}</table>` : "<p>none</p>") +
      rounds + verify;
    document.getElementById("diagram").appendChild(data.points.length ? phaseDiagram(data) : document.createTextNode("no points yet"));
    for (const s of main.querySelectorAll("#slice select")) {
      s.onchange = () => {
        const d = s.dataset.dim;
        const values = [...new Set(data.points.map((p) => p.coords[d]))].sort((a, b) => a < b ? -1 : a > b ? 1 : 0);
        slice[d] = values[Number(s.value)];
        draw(data);
      };
    }
    for (const a of main.querySelectorAll("#failures .run-link")) {
      a.onclick = async () => {
        const f = (data.failures || []).find((x) => x.run_id === a.dataset.run);
        const pt = f && data.points.find((q) => q.index === f.point);
        if (pt) { selected = where(pt.coords); shownRun = a.dataset.run; await showPoint(data, pt); }
      };
    }
    if (selected) {
      const p2 = data.points.find((pt) => where(pt.coords) === selected);
      if (p2) { showPoint(data, p2); }
    }
  }

  let page = null; // the campaign's page as last drawn: updates are applied to it
  function apply(delta) {
    if (!page || !delta.delta) { return delta; }
    const points = new Map(page.points.map((p) => [p.index, p]));
    for (const p of delta.points) { points.set(p.index, p); }
    const failures = new Map(page.failures.map((f) => [f.run_id, f]));
    for (const r of delta.cleared) { failures.delete(r); }
    for (const f of delta.failures) { failures.set(f.run_id, f); }
    return Object.assign({}, delta, {points: [...points.values()].sort((a, b) => a.index - b.index),
      failures: [...failures.values()], delta: false, cleared: []});
  }
  async function drawCampaign() {
    const url = `/api/campaigns/${encodeURIComponent(name)}` + (page ? `?since=${seq}` : "");
    const answer = await api(url);
    body.dataset.updates = String(Number(body.dataset.updates || 0) + (answer.delta ? 1 : 0));
    page = apply(answer);
    seq = page.seq;
    draw(page);
    body.dataset.ok = String(page.counts ? page.counts.ok : 0);
    body.dataset.seq = String(seq);
    body.dataset.delta = String(answer.delta);
  }

  // ------------------------------------------------------------------ updates
  async function refresh() {
    if (busy) { again = true; return; }
    busy = true;
    try {
      do { again = false; await (kind === "index" ? drawIndex() : drawCampaign()); } while (again);
      body.dataset.updated = String(Date.now());
    } catch (e) {
      live.textContent = "error: " + e.message;
    } finally { busy = false; }
  }
  function onChange() { refresh(); }
  function listen() {
    const source = new EventSource("/api/events");
    source.addEventListener("change", () => { live.textContent = "live"; live.className = "on"; onChange(); });
    source.onerror = () => { live.textContent = "reconnecting"; live.className = ""; };
  }
  refresh().then(listen);
})();
