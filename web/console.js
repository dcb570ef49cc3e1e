// manikind console: live state over one WebSocket (/ws), commands through POST /api/command with
// the API token. Everything comes from this daemon; nothing is loaded from anywhere else.
"use strict";

const STAGES = ["configuring", "chamber_settling", "manikin_starting", "acquiring", "stopping", "computing"];

// Where each ANDI zone is drawn: [view, x, y, width, height]. Front view: the manikin's left on
// the viewer's right; back view: its left on the viewer's left. Every zone appears once.
const ZONE_SHAPES = {
  face: ["front", 82, 8, 36, 42], scalp: ["back", 82, 8, 36, 42],
  neck: ["front", 90, 50, 20, 14], upper_chest: ["front", 68, 64, 64, 46], abdomen: ["front", 70, 110, 60, 40],
  pelvis_front: ["front", 70, 150, 60, 30], crotch: ["front", 92, 180, 16, 14],
  upper_back: ["back", 68, 64, 64, 50], lower_back: ["back", 70, 114, 60, 40],
  buttock_l: ["back", 70, 154, 30, 40], buttock_r: ["back", 100, 154, 30, 40],
  shoulder_l: ["front", 132, 64, 20, 20], shoulder_r: ["front", 48, 64, 20, 20],
  upper_arm_front_l: ["front", 134, 84, 18, 56], upper_arm_front_r: ["front", 48, 84, 18, 56],
  upper_arm_back_l: ["back", 48, 70, 18, 70], upper_arm_back_r: ["back", 134, 70, 18, 70],
  forearm_front_l: ["front", 137, 140, 16, 58], forearm_front_r: ["front", 47, 140, 16, 58],
  forearm_back_l: ["back", 47, 140, 16, 58], forearm_back_r: ["back", 137, 140, 16, 58],
  hand_l: ["front", 138, 198, 18, 30], hand_r: ["front", 44, 198, 18, 30],
  thigh_front_l: ["front", 102, 194, 27, 96], thigh_front_r: ["front", 71, 194, 27, 96],
  thigh_back_l: ["back", 71, 194, 27, 96], thigh_back_r: ["back", 102, 194, 27, 96],
  calf_front_l: ["front", 104, 290, 23, 88], calf_front_r: ["front", 73, 290, 23, 88],
  calf_back_l: ["back", 73, 290, 23, 88], calf_back_r: ["back", 104, 290, 23, 88],
  foot_top_l: ["front", 102, 378, 30, 20], foot_top_r: ["front", 68, 378, 30, 20],
  foot_sole_l: ["back", 68, 378, 30, 20], foot_sole_r: ["back", 102, 378, 30, 20],
};

const $ = (id) => document.getElementById(id);
const SVG = "http://www.w3.org/2000/svg";
let zones = [];
let latest = null;
const stageSeen = {};  // stage -> first time this page saw it (ms)

function fmt(v, digits = 2) {
  return v === null || v === undefined || Number.isNaN(v) ? "—" : Number(v).toFixed(digits);
}
function minutes(s) { return s === null || s === undefined ? "—" : (s / 60).toFixed(1) + " min"; }
function el(tag, attrs = {}, text) {
  const e = tag.startsWith("svg:") ? document.createElementNS(SVG, tag.slice(4)) : document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  return e;
}

// Blue (cold) to red (hot) through yellow, as the legend shows.
function colour(fraction) {
  const stops = [[44, 123, 182], [171, 217, 233], [255, 255, 191], [253, 174, 97], [215, 25, 28]];
  const f = Math.min(1, Math.max(0, fraction)) * (stops.length - 1);
  const i = Math.min(stops.length - 2, Math.floor(f));
  const t = f - i;
  const c = stops[i].map((a, k) => Math.round(a + (stops[i + 1][k] - a) * t));
  return `rgb(${c[0]},${c[1]},${c[2]})`;
}

function drawBody() {
  for (const view of ["front", "back"]) {
    const svg = $("body-" + view);
    svg.appendChild(el("svg:text", { x: 4, y: 12, class: "view-label" }, view));
  }
  for (const z of zones) {
    const shape = ZONE_SHAPES[z.name];
    if (!shape) continue;
    const [view, x, y, w, h] = shape;
    const r = el("svg:rect", { x, y, width: w, height: h, rx: Math.min(w, h) / 3, class: "zone nodata",
                               id: "zone-" + z.zone, "data-zone": z.zone, "data-name": z.name });
    r.appendChild(el("svg:title", {}, `${z.zone} ${z.name}`));
    r.addEventListener("mouseenter", () => showZone(z));
    $("body-" + view).appendChild(r);
  }
}

// Fixed colour scales (docs/daemon.md, "Console"), so a colour means the same value in every
// trial: 0.07 °C of spread no longer fills blue to red. Values beyond clip to the end colour.
const ZONE_SCALES = {
  skin_temp_c: { lo: 30, hi: 40, unit: "°C" },
  deviation: { lo: -0.5, hi: 0.5, unit: "°C from the setpoint" },
  heat_flux_w_m2: { lo: -100, hi: 300, unit: "W/m² (positive: heat lost)" },
  heater_power_w_m2: { lo: 0, hi: 400, unit: "W/m²" },
  residual: { lo: -20, hi: 20, unit: "W/m² measured − twin" },
};
// A zone is off its setpoint beyond this (the steady-state rule's order of magnitude, x4).
const OFF_SETPOINT_C = 0.2;

function zoneSetpoint(z) {
  const t = latest && latest.status ? latest.status.trial : null;
  if (!t) return null;
  if (t.zone_setpoints_c && t.zone_setpoints_c.length >= z.zone && t.zone_setpoints_c[z.zone - 1] !== null) return t.zone_setpoints_c[z.zone - 1];
  return t.skin_setpoint_c === undefined ? null : t.skin_setpoint_c;
}

function zoneReading(z, quantity) {
  if (!latest) return null;
  return latest.live[`manikin/z${String(z.zone).padStart(2, "0")}.${quantity}`] || null;
}

function zoneValue(z, quantity) {
  if (!latest) return null;
  if (quantity === "residual") {  // measured minus the baseline twin at the live conditions
    // The twin predicts a heated manikin in steady exchange: before the trial acquires (an idle or
    // starting manikin) the difference is no mismatch, so it is not shown.
    if (!latest.status || latest.status.stage !== "acquiring") return null;
    const measured = zoneValue(z, "heat_flux_w_m2");
    const twin = latest.twin_q_w_m2 ? latest.twin_q_w_m2[String(z.zone)] : undefined;
    return measured === null || twin === undefined || twin === null ? null : measured - twin;
  }
  if (quantity === "deviation") {
    const skin = zoneValue(z, "skin_temp_c"), sp = zoneSetpoint(z);
    return skin === null || sp === null ? null : skin - sp;
  }
  const v = zoneReading(z, quantity);
  return v ? v.value : null;
}

// Why a zone is marked: its sensor flagged by the manikin, its reading stale, or off its setpoint.
function zoneMark(z) {
  const r = zoneReading(z, "skin_temp_c");
  if (r && r.quality && r.quality !== "good") return `faulted (${r.quality})`;
  if (r && r.age_s > 10) return `stale (${fmt(r.age_s, 0)} s old)`;
  const d = zoneValue(z, "deviation");
  if (d !== null && Math.abs(d) > OFF_SETPOINT_C && latest.status.stage === "acquiring") return `off setpoint by ${fmt(d, 2)} °C`;
  return "";
}

function showZone(z) {
  const q = $("zone-quantity").value;
  const mark = zoneMark(z);
  const v = zoneValue(z, q);
  const why = v === null && q === "residual" ? " (shown while a trial is acquiring)" : "";
  $("zone-hover").textContent = `zone ${z.zone} ${z.name.replaceAll("_", " ")}: ${fmt(v)} ${ZONE_SCALES[q].unit}${why}` +
    (mark ? ` · ${mark}` : "");
}

function paintZones() {
  const q = $("zone-quantity").value;
  const { lo, hi, unit } = ZONE_SCALES[q];
  for (const z of zones) {
    const r = $("zone-" + z.zone);
    if (!r) continue;
    const v = zoneValue(z, q);
    const mark = zoneMark(z);
    r.setAttribute("data-value", v === null ? "" : v.toFixed(3));
    r.setAttribute("data-mark", mark);
    r.classList.toggle("nodata", v === null);
    r.classList.toggle("marked", mark !== "");
    r.style.fill = v === null ? "" : colour((v - lo) / (hi - lo));
    r.firstChild.textContent = `${z.zone} ${z.name}: ${fmt(v)} ${unit}${mark ? " · " + mark : ""}`;
  }
  const legend = $("zone-legend");
  legend.innerHTML = "";
  // Positioned through the CSSOM: the page's Content-Security-Policy refuses style attributes.
  const low = el("span", {}, `${fmt(lo, lo % 1 ? 1 : 0)}`), mid = el("span", {}, unit), high = el("span", {}, `${fmt(hi, hi % 1 ? 1 : 0)}`);
  low.style.left = "0";
  mid.style.left = "35%";
  high.style.right = "0";
  legend.append(low, mid, high);
  renderZoneTable();
}

// Every zone in one table: skin, setpoint, deviation, heat flux, heater power, quality and age,
// the marked ones first.
function renderZoneTable() {
  const body = $("zone-table").querySelector("tbody");
  const rows = zones.map((z) => ({ z, mark: zoneMark(z) })).sort((a, b) => (b.mark !== "") - (a.mark !== "") || a.z.zone - b.z.zone);
  body.replaceChildren(...rows.map(({ z, mark }) => {
    const skin = zoneReading(z, "skin_temp_c");
    const tr = el("tr", { "data-zone": z.zone, class: mark ? "marked" : "" });
    tr.append(el("td", {}, `${z.zone} ${z.name.replaceAll("_", " ")}`), el("td", {}, fmt(zoneValue(z, "skin_temp_c"), 2)),
      el("td", {}, fmt(zoneSetpoint(z), 2)), el("td", {}, fmt(zoneValue(z, "deviation"), 2)),
      el("td", {}, fmt(zoneValue(z, "heat_flux_w_m2"), 1)), el("td", {}, fmt(zoneValue(z, "heater_power_w_m2"), 1)),
      el("td", {}, skin ? `${skin.quality}, ${fmt(skin.age_s, 0)} s` : "—"), el("td", {}, mark));
    return tr;
  }));
}

// The model's core and mean skin at each update (issue 64: the model could not be watched), on
// the lab's clock; a new physiological trial starts a new trend.
let modelTrend = [];
function renderTrial(s) {
  const t = s.trial;
  $("campaign-line").textContent = s.campaign
    ? `${s.campaign}: ${s.trials_done} of ${s.trials_total} trials done` +
      (t ? ` · case ${t.case} replicate ${t.replicate} · ${fmt(t.stage_elapsed_s, 0)} s in stage` : "") +
      (s.paused ? " · paused" : "")
    : "no campaign running";
  const tl = $("stage-timeline");
  tl.innerHTML = "";
  const current = STAGES.indexOf(s.stage);
  if (!(s.stage in stageSeen)) stageSeen[s.stage] = Date.now();
  STAGES.forEach((name, i) => {
    const li = el("li", { "data-stage": name }, name.replaceAll("_", " "));
    if (i < current) li.className = "done";
    if (i === current) li.className = "current";
    tl.appendChild(li);
  });
  $("stage").textContent = s.stage;
  // How the manikin's zones are driven this trial (issue 65): what a reader of the zone chart must
  // know, since a comfort or constant-heat-flux trial's skin temperatures are not one setpoint.
  $("control-mode").hidden = !t;
  if (t) {
    let name = "constant skin temperature", detail = typeof t.skin_setpoint_c === "number" ? `${fmt(t.skin_setpoint_c, 1)} °C` : "";
    if (t.model) {
      name = "thermoregulation model";
      detail = "each zone's setpoint and sweat from the model";
    } else if (t.control === "comfort") {
      const eq = t.comfort_equation || {};
      name = "comfort mode";
      detail = `each zone's skin = ${fmt(eq.a_c, 1)} °C − ${fmt(eq.b_c_m2_w, 3)} °C·m²/W × its own heat loss`;
    } else if (t.control === "constant-heat-flux") {
      name = "constant heat flux";
      const regions = Object.entries(t.heat_flux_by_region_w_m2 || {}).map(([r, v]) => `${r} ${fmt(v, 0)}`).join(", ");
      detail = `${fmt(t.heat_flux_setpoint_w_m2, 0)} W/m² per zone${regions ? ` (${regions})` : ""}; the skin floats`;
    }
    $("control-name").textContent = name;
    $("control-detail").textContent = detail;
  }
  $("paused-banner").hidden = !s.paused;
  // Chamber settling: what is awaited, how far off each quantity is, and when it may be done.
  const st = t && t.settling;
  $("settling").hidden = !st;
  if (st) {
    $("settling-criterion").textContent = st.criterion;
    const off = (v, tol, unit) => {
      if (v === null || v === undefined) return el("span", {}, "no reading");
      const ok = Math.abs(v) <= tol;
      return el("span", { class: ok ? "" : "off" }, `${v >= 0 ? "+" : ""}${fmt(v, 2)} ${unit} ${ok ? "(within)" : "(off)"}`);
    };
    $("settling-air").replaceChildren(`${fmt(st.air_c, 2)} °C `, off(st.air_off_c, st.tolerance_c, "°C"));
    $("settling-rh").replaceChildren(`${fmt(st.rh_pct, 1)} % `, off(st.rh_off_pct, st.tolerance_rh_pct, "%"));
    $("settling-on").textContent = `${minutes(st.on_target_s)} of ${minutes(st.window_s)}`;
    // A first-order approach fitted to the last minutes, with its range; what still fails, by name.
    const range = (st.eta_high_s === null || st.eta_high_s === undefined) ? " or later" :
      ` (${minutes(st.eta_low_s)} to ${minutes(st.eta_high_s)})`;
    $("settling-eta").textContent = st.timed_out ? "timed out: holding (see alarms)"
      : (st.eta_s === null ? "unknown (not yet closing in)" : `in about ${minutes(st.eta_s)}${range}`)
      + ((st.failing || []).length ? `; not yet: ${st.failing.join("; ")}` : "");
  }

  // A physiological trial: the model's state beside the zones (status trial.model).
  const m = t && t.model;
  $("model-panel").hidden = !m;
  $("steady-section").hidden = !!m;  // a physiological trial has no steady state
  if (!m) modelTrend = [];
  if (m) {
    // The phase, how long it has run, and (preconditioning) when it falls back.
    $("model-phase").textContent = m.phase + (typeof m.phase_elapsed_s === "number" ? ` · ${minutes(m.phase_elapsed_s)}` +
      (typeof m.phase_limit_s === "number" ? ` of ${minutes(m.phase_limit_s)} before fallback` : "") : "");
    if (s.lab_utc_ms && (!modelTrend.length || modelTrend[modelTrend.length - 1].utc_ms < s.lab_utc_ms))
      modelTrend.push({ utc_ms: s.lab_utc_ms, core: m.core_temp_c, skin: m.mean_skin_temp_c });
    if (modelTrend.length > 3000) modelTrend.splice(0, modelTrend.length - 3000);
    chart("chart-model", modelTrend, [{ key: "core", cls: "measured", label: "core" },
      { key: "skin", cls: "pv", label: "mean skin" }], "model °C", 0.5);
    $("model-phase").className = "badge " + (m.phase === "fallback" ? "not-steady" : "steady");
    $("model-time").textContent = `${minutes(m.model_time_s)} of ${minutes(m.duration_s)} (${m.model})`;
    $("model-core").textContent = `${fmt(m.core_temp_c, 2)} °C`;
    $("model-skin").textContent = `${fmt(m.mean_skin_temp_c, 2)} °C`;
    const body = $("model-segments").querySelector("tbody");
    body.replaceChildren(...Object.entries(m.segments || {}).map(([name, seg]) => {
      const tr = el("tr");
      tr.append(el("td", {}, name), el("td", {}, fmt(seg.skin_temp_c, 2)), el("td", {}, fmt(seg.core_temp_c, 2)),
                el("td", {}, seg.heat_loss_w === null ? "— (not yet)" : fmt(seg.heat_loss_w, 1)));
      return tr;
    }));
    $("model-fallback").textContent = m.fallback_reason ? `fell back to constant skin temperature: ${m.fallback_reason}` : "";
  }

  const verdict = $("steady-verdict");
  if (t && t.limit_c !== undefined) {
    verdict.textContent = t.steady ? "STEADY" : "not steady";
    verdict.className = "badge " + (t.steady ? "steady" : "not-steady");
    verdict.setAttribute("data-steady", t.steady ? "true" : "false");
    $("steady-limit").textContent = fmt(t.limit_c, 2);
    $("steady-window").textContent = fmt(t.window_s / 60, 0);
    $("steady-min").textContent = fmt(t.min_duration_s / 60, 0);
    const worst = t.worst_zone ? ` (zone ${t.worst_zone.zone} ${t.worst_zone.name})` : "";
    $("steady-range").textContent = `${fmt(t.worst_zone_range_c, 3)} °C against ${fmt(t.limit_c, 2)} °C${worst}`;
    $("steady-window-filled").textContent = `${fmt(100 * t.window_filled_fraction, 0)} % of ${fmt(t.window_s / 60, 0)} min`;
    $("steady-elapsed").textContent = `${minutes(t.elapsed_s)} of at least ${minutes(t.min_duration_s)}`;
    // Earliest time the rule can hold if every zone stays within the limit from now on.
    const wait = Math.max(0, t.min_duration_s - t.elapsed_s, t.window_s * (1 - t.window_filled_fraction));
    $("steady-eta").textContent = t.steady ? "reached" : (t.worst_zone_range_c !== null && t.worst_zone_range_c > t.limit_c
      ? `in ≥ ${minutes(wait)} (a zone still varies beyond the limit)` : `in ${minutes(wait)}`);
    $("steady-bar").style.width = `${Math.floor(100 * (t.steady_progress || 0))}%`;
  } else {
    // Not acquiring: the rule's numbers are the running trial's, so say what is awaited instead
    // of a rule with blanks in it.
    verdict.textContent = "—";
    verdict.className = "badge";
    verdict.setAttribute("data-steady", "none");
    $("steady-bar").style.width = "0%";
    for (const id of ["steady-range", "steady-window-filled", "steady-elapsed", "steady-eta"]) $(id).textContent = "—";
  }
  $("steady-rule").hidden = !(t && t.limit_c !== undefined);
  $("steady-idle").hidden = !!(t && t.limit_c !== undefined);
  $("steady-idle").textContent = t ? `judged once the trial is acquiring (now: ${s.stage.replaceAll("_", " ")})`
    : "judged while a trial acquires; no trial is running";
}

function renderMeasured(s) {
  const m = s.measured || {};
  const rows = [["air temperature (EE181)", m.chamber_air_temp_c], ["relative humidity (EE181)", m.chamber_air_rh_pct],
                ["air speed (WindSonic)", m.air_speed_m_s], ["mean skin temperature", m.mean_skin_temp_c],
                ["mean heat flux", m.mean_heat_flux_w_m2]];
  const table = $("measured");
  table.innerHTML = "";
  table.appendChild(el("tr", {}, "")).innerHTML = "<th></th><th>value</th><th>setpoint</th><th>age</th>";
  for (const [label, v] of rows) {
    if (!v) continue;
    // A reading older than 10 s, or not good, is greyed: it is not the chamber now.
    const stale = (v.age_s !== null && v.age_s > 10) || (v.quality && v.quality !== "good");
    const tr = el("tr", { class: stale ? "stale" : "", title: stale ? `stale: ${v.quality || ""}, ${fmt(v.age_s, 0)} s old` : "" });
    tr.appendChild(el("th", {}, label));
    tr.appendChild(el("td", {}, `${fmt(v.value)} ${v.unit}`));
    tr.appendChild(el("td", {}, v.setpoint === undefined ? "" : `${fmt(v.setpoint, 1)} ${v.unit}`));
    tr.appendChild(el("td", {}, v.age_s === null ? "—" : `${fmt(v.age_s, 0)} s`));
    table.appendChild(tr);
  }
}

// A time-axis chart: the enclosure's reading (solid), the controller's PV (thin), the setpoint
// (dashed), with the unit, clock times under the axis and the span it covers. `minSpan` keeps a
// flat signal from filling the height with noise (air speed near zero reads "0.00 to 0.50").
function chart(id, points, series, unit, minSpan) {
  const svg = $(id);
  svg.innerHTML = "";
  const X0 = 44, X1 = 395, Y0 = 100, Y1 = 14;
  const have = (k) => points.filter((p) => p[k] !== null && p[k] !== undefined);
  const main = have(series[0].key);
  if (main.length < 2) {
    svg.appendChild(el("svg:text", { x: 8, y: 60 }, `${unit}: waiting for data`));
    return;
  }
  const values = [];
  for (const s of series) for (const p of have(s.key)) values.push(p[s.key]);
  let lo = Math.min(...values), hi = Math.max(...values);
  if (hi - lo < minSpan) { const mid = (hi + lo) / 2; lo = Math.max(unit.includes("m/s") ? 0 : -Infinity, mid - minSpan / 2); hi = lo + minSpan; }
  const t0 = points[0].utc_ms, t1 = points[points.length - 1].utc_ms, tspan = Math.max(t1 - t0, 1);
  const x = (p) => (X0 + (X1 - X0) * (p.utc_ms - t0) / tspan).toFixed(1);
  const y = (v) => (Y0 - (Y0 - Y1) * (v - lo) / (hi - lo)).toFixed(1);
  // Axes: value ticks at the ends and the middle, clock times at the ends and the middle.
  svg.appendChild(el("svg:line", { x1: X0, y1: Y0, x2: X1, y2: Y0, class: "axis" }));
  svg.appendChild(el("svg:line", { x1: X0, y1: Y1, x2: X0, y2: Y0, class: "axis" }));
  for (const f of [0, 0.5, 1]) {
    const v = lo + f * (hi - lo);
    svg.appendChild(el("svg:text", { x: X0 - 3, y: Number(y(v)) + 3, "text-anchor": "end" }, fmt(v, hi - lo < 2 ? 2 : 1)));
    const t = new Date(t0 + f * tspan);
    svg.appendChild(el("svg:text", { x: X0 + f * (X1 - X0), y: 114, "text-anchor": f === 0 ? "start" : f === 1 ? "end" : "middle" },
      t.toLocaleTimeString([], tspan < 10 * 60000 ? { hour: "2-digit", minute: "2-digit", second: "2-digit" } : { hour: "2-digit", minute: "2-digit" })));
  }
  for (const s of series) {
    const pts = have(s.key);
    if (pts.length > 1) svg.appendChild(el("svg:polyline", { class: s.cls, points: pts.map((p) => `${x(p)},${y(p[s.key])}`).join(" ") }));
  }
  const last = main[main.length - 1][series[0].key];
  svg.appendChild(el("svg:text", { x: X0 + 2, y: 10 }, `${unit} · now ${fmt(last, 2)} · ${fmt(tspan / 60000, 0)} min`));
  let lx = 250;
  for (const s of series) {
    if (!have(s.key).length) continue;
    svg.appendChild(el("svg:line", { x1: lx, y1: 7, x2: lx + 12, y2: 7, class: s.cls }));
    svg.appendChild(el("svg:text", { x: lx + 14, y: 10 }, s.label));
    lx += 20 + 5.5 * s.label.length;
  }
}

let historySpan = "1h";
async function renderHistory() {
  const h = await (await fetch(`/api/history?span=${historySpan}`)).json();
  const points = h.points || [];
  chart("chart-temp", points, [{ key: "air_temp_c", cls: "measured", label: "probe" },
    { key: "air_temp_pv_c", cls: "pv", label: "PV" }, { key: "air_temp_setpoint_c", cls: "setpoint", label: "setpoint" }], "air °C", 0.5);
  chart("chart-rh", points, [{ key: "air_rh_pct", cls: "measured", label: "probe" },
    { key: "air_rh_pv_pct", cls: "pv", label: "PV" }, { key: "air_rh_setpoint_pct", cls: "setpoint", label: "setpoint" }], "RH %", 2);
  chart("chart-speed", points, [{ key: "air_speed_m_s", cls: "measured", label: "WindSonic" }], "air speed m/s", 0.5);
  const from = h.covers_from_utc_ms ? new Date(h.covers_from_utc_ms).toLocaleString() : "—";
  // The charts run on the lab's clock (a simulated lab's own, sped up or not), as its records do.
  const clock = latest && latest.status && latest.status.clock !== "real" ? " on the simulated lab's clock" : "";
  $("history-note").textContent = `span: ${h.span === "1h" ? "last hour" : h.span}${clock}, from ${from}` +
    (h.span !== "1h" && !(h.span === "trial" ? h.trial_start_utc_ms : h.campaign_start_utc_ms) ? " (none seen since the console's daemon started)" : "");
}

function renderDevices(s) {
  const table = $("devices");
  table.innerHTML = "<tr><th>device</th><th>severity</th><th>samples</th><th>errors</th><th>reconnects</th></tr>";
  // The last error on a line of its own under its device: it is a sentence, and in a column of its
  // own it pushed the table past its panel.
  for (const d of s.devices) {
    const tr = el("tr", { id: "device-" + d.name, "data-severity": d.severity });
    tr.appendChild(el("td", {}, d.name));
    const sev = el("td");
    sev.appendChild(el("span", { class: "badge " + d.severity, title: d.severity_reason }, d.severity));
    tr.appendChild(sev);
    tr.appendChild(el("td", {}, String(d.samples)));
    // Every kind the driver counts: failed reads, writes and opens (comm_errors) too.
    const errors = d.checksum_errors + d.timeouts + d.exceptions + d.malformed + d.device_faults + (d.comm_errors || 0);
    tr.appendChild(el("td", {}, String(errors)));
    tr.appendChild(el("td", {}, String(d.reconnects)));
    table.appendChild(tr);
    if (d.last_error) {
      const why = el("tr", { class: "last-error", id: "device-" + d.name + "-last-error" });
      why.appendChild(el("td", { colspan: "5" }, `last error: ${d.last_error}`));
      table.appendChild(why);
    }
  }
}

// ISA-18.2 states (daemon/alarm_book.hpp): what each means to the operator.
const ALARM_STATE_TEXT = {
  UNACK: "active, not acknowledged",
  ACKED: "active, acknowledged",
  RTN_UNACK: "returned to normal, not acknowledged",
  SHELVED: "shelved",
};

function renderAlarms(alarms) {
  const table = $("alarms");
  table.innerHTML = "<tr><th>raised</th><th>severity</th><th>state</th><th>what</th><th></th></tr>";
  // Active ones first (unacknowledged before acknowledged), then returned, then shelved; newest first within.
  const rank = { UNACK: 0, ACKED: 1, RTN_UNACK: 2, SHELVED: 3 };
  const shown = alarms.slice().sort((a, b) => (rank[a.state] ?? 4) - (rank[b.state] ?? 4) || b.id - a.id).slice(0, 20);
  const active = alarms.filter((a) => a.state === "UNACK" || a.state === "ACKED").length;
  $("alarm-count").textContent = alarms.length
    ? `${active} active · ${alarms.length - active} returned or shelved (${alarms.length} open)` : "none open";
  for (const a of shown) {
    const tr = el("tr", { "data-alarm": a.id, "data-state": a.state || "", class: "alarm-" + (a.state || "").toLowerCase() });
    tr.appendChild(el("td", {}, new Date(a.utc_ms).toLocaleTimeString()));
    const sev = el("td");
    sev.appendChild(el("span", { class: "badge " + a.severity }, a.severity));
    tr.appendChild(sev);
    let state = ALARM_STATE_TEXT[a.state] || a.state || "";
    if (a.state === "SHELVED" && a.shelved_until_utc_ms) state += ` until ${new Date(a.shelved_until_utc_ms).toLocaleTimeString()}`;
    if (a.acknowledged && a.acknowledged_by) state += ` (by ${a.acknowledged_by})`;
    tr.appendChild(el("td", {}, state));
    let what = `${a.kind}: ${a.message}`;
    if (a.count > 1) what += ` (×${a.count})`;
    if (a.cleared_message) what += ` → ${a.cleared_message}`;
    tr.appendChild(el("td", {}, what));
    const actions = el("td");
    if (!a.acknowledged) {
      const b = el("button", {}, "Acknowledge");
      b.addEventListener("click", () => command({ cmd: "ack_alarm", id: a.id }));
      actions.appendChild(b);
    }
    if (a.state === "SHELVED") {
      const b = el("button", {}, "Unshelve");
      b.addEventListener("click", () => command({ cmd: "unshelve_alarm", id: a.id }));
      actions.appendChild(b);
    } else {
      const b = el("button", { title: "hide it for one hour; it comes back by itself" }, "Shelve 1 h");
      b.addEventListener("click", () => command({ cmd: "shelve_alarm", id: a.id, duration_s: 3600 }));
      actions.appendChild(b);
    }
    tr.appendChild(actions);
    table.appendChild(tr);
  }
}

function renderQueue(s) {
  const q = $("queue");
  q.textContent = (s.campaign ? `running: ${s.campaign}` : "nothing running") +
    (s.queued_campaigns && s.queued_campaigns.length ? ` · queued: ${s.queued_campaigns.join(", ")}` : "");
}

let resultsShownFor = null;
async function renderResults(s) {
  const name = s.campaign || null;
  const key = `${name}:${s.trials_done}`;
  if (key === resultsShownFor) return;
  resultsShownFor = key;
  const r = await fetch("/api/results" + (name ? "?campaign=" + encodeURIComponent(name) : ""));
  if (!r.ok) {
    $("results").innerHTML = "<tr><td>results appear when a campaign's cases have been analysed</td></tr>";
    return;
  }
  const body = await r.json();
  const cases = (body.results && body.results.cases) || [];
  const table = $("results");
  table.innerHTML = "<tr><th>case</th><th>n</th><th>Q whole body</th><th>95 % CI</th></tr>";
  for (const c of cases) {
    const wb = c.whole_body || {};
    const tr = el("tr");
    tr.appendChild(el("td", {}, String(c.case)));
    tr.appendChild(el("td", {}, String(c.n_replicates)));
    tr.appendChild(el("td", {}, `${fmt(wb.q_w_m2)} W/m²`));
    tr.appendChild(el("td", {}, `[${fmt(wb.ci_low_w_m2)}, ${fmt(wb.ci_high_w_m2)}]`));
    table.appendChild(tr);
  }
  $("results-campaign").textContent = body.campaign + (body.results.interim ? " (so far: interim, updated after each trial)" : "");
  drawParity(body.results.twin_parity || []);
}

// Measured whole-body flux (with its 95 % CI) against the baseline twin's, per case; the
// diagonal is agreement. Points off it are what `manikin reconcile` explains.
function drawParity(points) {
  const svg = $("results-plot");
  svg.innerHTML = "";
  if (!points.length) return;
  const all = points.flatMap((p) => [p.twin_w_m2, p.measured_w_m2 - p.U_w_m2, p.measured_w_m2 + p.U_w_m2]);
  const lo = Math.min(...all), hi = Math.max(...all), span = hi - lo > 1e-6 ? hi - lo : 1;
  const x = (v) => 50 + 330 * (v - lo) / span, y = (v) => 145 - 130 * (v - lo) / span;
  svg.appendChild(el("svg:line", { x1: x(lo), y1: y(lo), x2: x(hi), y2: y(hi), stroke: "#999", "stroke-dasharray": "4 3" }));
  for (const p of points) {
    const g = el("svg:g", { class: "parity-point", "data-case": p.case });
    g.appendChild(el("svg:line", { x1: x(p.twin_w_m2), x2: x(p.twin_w_m2), y1: y(p.measured_w_m2 - p.U_w_m2),
                                   y2: y(p.measured_w_m2 + p.U_w_m2), stroke: "#1d6fb8" }));
    g.appendChild(el("svg:circle", { cx: x(p.twin_w_m2), cy: y(p.measured_w_m2), r: 3, fill: "#1d6fb8" }));
    g.appendChild(el("svg:title", {}, `case ${p.case}: measured ${fmt(p.measured_w_m2)} ± ${fmt(p.U_w_m2)} W/m², twin ${fmt(p.twin_w_m2)} W/m²`));
    svg.appendChild(g);
  }
  svg.appendChild(el("svg:text", { x: 2, y: 14 }, `measured ${fmt(hi, 0)}`));
  svg.appendChild(el("svg:text", { x: 2, y: 150 }, fmt(lo, 0)));
  svg.appendChild(el("svg:text", { x: 250, y: 158 }, "baseline twin, W/m² →"));
}

// True when the daemon did it.
async function command(body) {
  body.token = $("token").value;
  const out = $("command-result");
  try {
    const r = await fetch("/api/command", { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) });
    const j = await r.json();
    let text = j.ok ? `${body.cmd}: done` : `${body.cmd} refused: ${j.error}`;
    if (!j.ok && /token/.test(j.error || "")) text += " (the token: see the note under the token field)";
    out.textContent = text;
    out.className = j.ok ? "ok" : "error";
    return !!j.ok;
  } catch (e) {
    out.textContent = `${body.cmd}: no answer (${e})`;
    out.className = "error";
    return false;
  }
}

// The campaign's notebook, newest first (text shown as text, never as markup).
async function renderNotes(campaign) {
  const list = $("notes-list");
  if (!campaign) { list.textContent = ""; return; }
  try {
    const r = await fetch(`/api/notes?campaign=${encodeURIComponent(campaign)}`);
    if (!r.ok) return;
    const notes = await r.json();
    list.textContent = "";
    for (const n of notes.slice().reverse().slice(0, 10)) {
      const about = n.trial_id === null ? "campaign" : `trial ${n.trial_id}`;
      list.appendChild(el("li", {}, `${n.utc} · ${n.author} · ${n.kind} · ${about}: ${n.text}`));
    }
  } catch (e) { /* the connection badge says when the daemon is gone */ }
}

function onUpdate(msg) {
  latest = msg;
  const s = msg.status;
  $("last-update").textContent = new Date(msg.server_utc_ms || Date.now()).toLocaleTimeString();
  $("hdr-stage").textContent = (s.stage || "—").replaceAll("_", " ") + (s.paused ? " (PAUSED)" : "");
  // What the daemon waits for the operator to do (dress the manikin), with the button that says done.
  $("operator-banner").hidden = typeof s.awaiting_operator !== "string";
  $("operator-prompt").textContent = s.awaiting_operator || "";
  const active = (msg.alarms || []).filter((a) => a.state === "UNACK" || a.state === "ACKED").length;
  const unacked = (msg.alarms || []).filter((a) => !a.acknowledged).length;
  $("hdr-alarms").textContent = `alarms: ${active} active, ${unacked} to acknowledge`;
  $("hdr-alarms").className = "badge " + (active ? "MAJOR" : unacked ? "MINOR" : "NO_ALARM");
  const clock = s.clock === "paced" ? `simulated time at ${s.speed}× the wall clock` : `${s.clock} clock`;
  const labClock = s.lab_utc_ms ? `lab clock ${new Date(s.lab_utc_ms).toLocaleTimeString()} · ` : "";
  $("lab").textContent = `${s.mode} lab · ${clock} · ${labClock}t = ${fmt(s.time_s, 0)} s`;
  renderTrial(s);
  renderMeasured(s);
  renderDevices(s);
  renderQueue(s);
  renderAlarms(msg.alarms || []);
  paintZones();
  document.body.setAttribute("data-updates", String(Number(document.body.getAttribute("data-updates") || 0) + 1));
}

function connect() {
  const ws = new WebSocket(`ws://${location.host}/ws`);
  ws.onopen = () => {
    $("connection").textContent = "live";
    $("connection").className = "badge NO_ALARM";
    document.body.classList.remove("disconnected");
    $("disconnected-banner").hidden = true;
    for (const b of document.querySelectorAll("header button")) b.disabled = false;
  };
  ws.onmessage = (e) => onUpdate(JSON.parse(e.data));
  ws.onclose = () => {
    // Impossible to miss: the page greys out under a banner saying how old its values are.
    $("connection").textContent = "DISCONNECTED";
    $("connection").className = "badge MAJOR";
    document.body.classList.add("disconnected");
    $("disconnected-banner").hidden = false;
    // Nothing in the header may look live: the buttons could not reach the daemon anyway.
    for (const b of document.querySelectorAll("header button")) b.disabled = true;
    setTimeout(connect, 2000);
  };
}

async function main() {
  zones = await (await fetch("/api/zones")).json();
  drawBody();
  $("zone-quantity").addEventListener("change", paintZones);
  $("pause").addEventListener("click", () => command({ cmd: "pause" }));
  $("resume").addEventListener("click", () => command({ cmd: "resume" }));
  // The header's copies: the same commands; Abort opens the confirmation below (name and reason).
  $("hdr-pause").addEventListener("click", () => command({ cmd: "pause" }));
  $("operator-continue").addEventListener("click", () => command({ cmd: "continue" }));
  $("hdr-resume").addEventListener("click", () => command({ cmd: "resume" }));
  $("hdr-abort").addEventListener("click", () => { $("abort").click(); $("control-panel").scrollIntoView(); });
  // Abort asks first: the campaign's name typed, and a reason (both recorded by the daemon).
  $("abort").addEventListener("click", () => {
    const running = latest && latest.status ? latest.status.campaign : null;
    $("abort-name").textContent = running ? running : "(none running)";
    $("abort-typed").value = "";
    $("abort-confirm").hidden = false;
    $("abort-typed").focus();
  });
  $("abort-cancel").addEventListener("click", () => { $("abort-confirm").hidden = true; });
  $("abort-confirm").addEventListener("submit", (e) => {
    e.preventDefault();
    command({ cmd: "abort", confirm: $("abort-typed").value, reason: $("abort-reason").value || "aborted from the console" });
    $("abort-confirm").hidden = true;
  });
  $("note-form").addEventListener("submit", async (e) => {
    e.preventDefault();
    const s = latest && latest.status ? latest.status : {};
    const campaign = $("note-campaign").value.trim() || s.campaign || s.last_campaign || "";
    const body = { cmd: "note", campaign, kind: $("note-kind").value, text: $("note-text").value };
    if ($("note-author").value.trim()) body.author = $("note-author").value.trim();
    if ($("note-trial").checked) {
      if (!s.trial || !s.trial.id) { $("command-result").textContent = "note: no trial is running"; $("command-result").className = "error"; return; }
      body.trial = s.trial.id;
    }
    if (await command(body)) { $("note-text").value = ""; renderNotes(campaign); }
  });
  for (const b of document.querySelectorAll("#history-span button")) {
    b.addEventListener("click", () => {
      historySpan = b.dataset.span;
      for (const o of document.querySelectorAll("#history-span button")) o.classList.toggle("chosen", o === b);
      renderHistory();
    });
  }
  connect();
  renderHistory();
  setInterval(renderHistory, 5000);
  setInterval(() => { if (latest) renderResults(latest.status); }, 5000);
  // The notebook of the campaign named in the form, else the running (or last) one.
  const notesCampaign = () => $("note-campaign").value.trim() || (latest && latest.status && (latest.status.campaign || latest.status.last_campaign)) || "";
  setInterval(() => renderNotes(notesCampaign()), 5000);
}

document.addEventListener("DOMContentLoaded", main);
