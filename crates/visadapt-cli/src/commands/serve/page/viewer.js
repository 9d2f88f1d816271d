// The visadapt viewer page. It only asks the server: every frame, number and pixel reading
// comes from the library through /api/frame, /api/report and /api/pixel. No model here.
"use strict";

const $ = (id) => document.getElementById(id);
const state = { width: 0, height: 0, nativeLevel: null, nativeExact: true, playing: false, lastTick: 0, lastReport: 0 };
// Fig. 12 of the paper (Sec. 5): 0.1 -> 5623 cd/m² seen for 75 s; 1412 -> 0.1 cd/m² for 3.5 min.
const FIG12 = {
  fig12a: { from: 0.1, to: 5623, tMax: 75, speed: 5 },
  fig12b: { from: 1412, to: 0.1, tMax: 210, speed: 10 },
};

function level() {
  return Math.pow(10, Number($("level").value));
}

function fmt(v, unit) {
  if (v === null || v === undefined) return "n/a";
  if (typeof v !== "number") return String(v);
  const a = Math.abs(v);
  let s;
  if (a === 0) s = "0";
  else if (a >= 1e5 || a < 1e-3) s = v.toExponential(2);
  else if (a >= 100) s = v.toFixed(0);
  else s = v.toPrecision(3);
  return unit ? s + " " + unit : s;
}

// The query of the current controls; `extra` adds or overrides parameters.
function query(extra) {
  const p = new URLSearchParams();
  // Until the first report the page shows the file's own level (no peak).
  const moved = state.nativeLevel !== null && Math.abs(Number($("level").value) - state.nativeLevel) > 1e-9;
  if (moved || (state.nativeLevel !== null && !state.nativeExact)) {
    p.set("peak", level().toPrecision(6));
  }
  const dmax = Number($("display-max").value);
  if (dmax > 0) p.set("display_max", String(dmax));
  const fov = $("fov").value.trim();
  if (fov !== "") p.set("fov", fov);
  p.set("acuity", $("acuity").checked ? "1" : "0");
  // Until the first report the server's flags (--glare, --adaptation) set these.
  if (state.nativeLevel !== null) {
    p.set("glare", $("glare").checked ? "1" : "0");
    p.set("adaptation", $("adaptation").value);
  }
  if ($("timecourse").checked) {
    p.set("from", String(Number($("from").value)));
    p.set("t", String(Number($("t").value)));
  }
  for (const [k, v] of Object.entries(extra || {})) {
    if (v === null) p.delete(k);
    else p.set(k, String(v));
  }
  return p.toString();
}

// The preview is as wide as it shows on screen (the image fits the view's width and the
// window's height), in device pixels, at most 1280 and at most the image.
function previewWidth() {
  const boxW = $("view").clientWidth || 800;
  const boxH = Math.max(100, window.innerHeight - 100);
  const fit = state.width && state.height ? Math.min(boxW, (boxH * state.width) / state.height) : boxW;
  const want = Math.round(fit * (window.devicePixelRatio || 1));
  return Math.max(1, Math.min(state.width || want, want, 1280));
}

function say(text, isError) {
  const s = $("status");
  s.textContent = text;
  s.className = isError ? "error" : "";
}

// One request of each kind in flight; a change meanwhile asks again when it is done, so
// the page never queues stale frames (latest wins).
function channel(run) {
  let busy = false;
  let again = false;
  const ch = {
    pending: () => busy || again,
    kick() {
      if (busy) {
        again = true;
        return;
      }
      busy = true;
      again = false;
      run()
        .catch((e) => say(e.message, true))
        .finally(() => {
          busy = false;
          if (again) ch.kick();
          updateBusy();
        });
      updateBusy();
    },
  };
  return ch;
}

async function fetchOk(url) {
  const r = await fetch(url, { cache: "no-store" });
  if (!r.ok) throw new Error((await r.text()).trim() || r.status + " " + r.statusText);
  return r;
}

// Load a frame into `img`; returns what the server says the frame shows.
async function loadImage(img, url) {
  const r = await fetchOk(url);
  const showing = r.headers.get("x-visadapt-showing") || "";
  const blob = await r.blob();
  const src = URL.createObjectURL(blob);
  await new Promise((resolve, reject) => {
    img.onload = resolve;
    img.onerror = () => reject(new Error("the frame did not decode"));
    img.src = src;
  });
  if (img.dataset.url) URL.revokeObjectURL(img.dataset.url);
  img.dataset.url = src;
  return showing;
}

const frames = channel(async () => {
  const started = performance.now();
  const q = query({ width: previewWidth() });
  const showing = await loadImage($("frame"), "/api/frame?" + q);
  $("showing").textContent = "showing: " + showing;
  if ($("split").checked) {
    await loadImage($("exposure"), "/api/frame?" + query({ width: previewWidth(), mode: "exposure" }));
  }
  document.body.dataset.frames = String(Number(document.body.dataset.frames) + 1);
  $("full").href = "/api/frame?" + query();
  say("frame in " + Math.round(performance.now() - started) + " ms", false);
  if (state.playing) requestAnimationFrame(tick);
});

const reports = channel(async () => {
  const r = await (await fetchOk("/api/report?" + query())).json();
  showReport(r);
  document.body.dataset.reports = String(Number(document.body.dataset.reports) + 1);
});

let pointer = null;
const pixels = channel(async () => {
  if (!pointer) return;
  const q = query({ width: previewWidth(), x: pointer.x, y: pointer.y, change: Number($("change").value) / 100 });
  showPixel(await (await fetchOk("/api/pixel?" + q)).json());
});

function updateBusy() {
  const waiting = frames.pending() || reports.pending() || state.nativeLevel === null;
  document.body.dataset.busy = waiting ? "1" : "0";
}

function refresh() {
  $("level-value").textContent = fmt(level(), "cd/m²");
  $("clock").textContent = "t = " + fmt(Number($("t").value), "s");
  frames.kick();
  // While the time course plays, the report (which counts pixels at full resolution)
  // follows once a second; every frame still comes from the server.
  const now = performance.now();
  if (!state.playing || now - state.lastReport > 1000) {
    state.lastReport = now;
    reports.kick();
  }
  if (pointer) pixels.kick();
}

function row(tbody, name, value) {
  const tr = document.createElement("tr");
  const th = document.createElement("th");
  const td = document.createElement("td");
  th.textContent = name;
  td.textContent = value;
  tr.append(th, td);
  tbody.append(tr);
}

function showReport(r) {
  state.width = r.width;
  state.height = r.height;
  const tb = $("report").tBodies[0];
  tb.replaceChildren();
  const tc = r.time_course;
  row(tb, "image", r.width + " × " + r.height);
  row(tb, "highest visible", fmt(r.highest_visible_cd_m2, "cd/m²"));
  row(tb, "adaptation (Sec. 4.4)", fmt(r.adaptation_cd_m2, "cd/m²") + ", " + fmt(r.scotopic_adaptation_cd_m2, "scotopic cd/m²"));
  if (tc) {
    row(tb, "t after the switch", fmt(tc.t_seconds, "s") + (tc.adapted ? " (adapted)" : ""));
    row(tb, "cone threshold now", fmt(tc.cone_threshold_cd_m2, "cd/m²") + " (+" + tc.cone_excess_log.toFixed(2) + " log)");
    row(tb, "rod threshold now", fmt(tc.rod_threshold_scotopic_cd_m2, "scotopic cd/m²") + " (+" + tc.rod_excess_log.toFixed(2) + " log)");
    row(tb, "rod weight k (Eq. 6)", tc.rod_weight.toFixed(3));
    row(tb, "scales m_p, m_s (Eq. 8)", fmt(tc.photopic_scale) + ", " + fmt(tc.scotopic_scale));
    row(tb, "acuity now", fmt(tc.acuity_cycles_per_degree, "c/deg") + " (" + tc.snellen + ")");
    row(tb, "once adapted", fmt(r.acuity_cycles_per_degree, "c/deg") + " (" + r.snellen + "), k " + r.rod_weight.toFixed(3));
  } else {
    row(tb, "thresholds (Eq. 4, 5)", fmt(r.cone_threshold_cd_m2, "cd/m²") + ", " + fmt(r.rod_threshold_scotopic_cd_m2, "scot."));
    row(tb, "rod weight k (Eq. 6)", r.rod_weight.toFixed(3));
    row(tb, "scales m_p, m_s (Eq. 3)", fmt(r.photopic_scale) + ", " + fmt(r.scotopic_scale));
    row(tb, "acuity (Fig. 7)", fmt(r.acuity_cycles_per_degree, "c/deg") + " (" + r.snellen + ")");
  }
  row(tb, "acuity blur", r.acuity_applied ? (r.blur_sigma_px > 0 ? "σ " + fmt(r.blur_sigma_px, "px") : "below a pixel") : "off");
  row(tb, "view", r.view.projection + " " + fmt(r.view.horizontal_fov_deg, "°") + " (" + r.view.source + ")");
  if (r.glare) {
    const g = r.glare;
    row(tb, "veiling glare", fmt(g.veil_at_fixation_cd_m2, "cd/m²") + " at the centre, " + fmt(100 * g.scattered_fraction) + " % scattered");
    row(tb, "adaptation with / without glare", "× " + g.adaptation_ratio.toFixed(3) + " (without: " + fmt(g.adaptation_without_glare_cd_m2, "cd/m²") + ")");
  }
  if (r.local) {
    const a = r.local.adaptation_cd_m2;
    const k = r.local.rod_weight;
    row(tb, "local adaptation (" + fmt(r.local.radius_deg, "°") + ")", fmt(a.p10) + " to " + fmt(a.p90, "cd/m²") + " (10-90 %)");
    row(tb, "local k (Eq. 6)", k.p10.toFixed(3) + " to " + k.p90.toFixed(3));
  }
  row(tb, "display", fmt(r.display_max_cd_m2, "cd/m²") + ", clipped " + r.pixels_clipped + " px");
  if (state.nativeLevel === null) {
    // First report: the server's view and the file's own level set the controls.
    $("fov").placeholder = fmt(r.view.horizontal_fov_deg) + " (" + r.view.source + ")";
    $("glare").checked = r.glare !== null;
    $("adaptation").value = r.adaptation;
    const l = Math.log10(r.highest_visible_cd_m2);
    $("level").value = String(Number.isFinite(l) ? l : 2);
    state.nativeLevel = Number($("level").value);
    state.nativeExact = Number.isFinite(l) && Math.abs(state.nativeLevel - l) < 0.006;
    refresh();
  }
}

function showPixel(p) {
  const tb = $("pixel").tBodies[0];
  tb.replaceChildren();
  row(tb, "pixel", p.x + ", " + p.y);
  row(tb, "world", fmt(p.luminance_cd_m2, "cd/m²") + ", " + fmt(p.scotopic_cd_m2, "scotopic cd/m²"));
  if (p.retinal_cd_m2 !== p.luminance_cd_m2) row(tb, "with the veil", fmt(p.retinal_cd_m2, "cd/m²"));
  row(tb, "displayed", fmt(p.display.luminance_cd_m2, "cd/m²") + ", sRGB " + p.display.srgb8.join(" "));
  row(tb, "smallest visible change", fmt(p.threshold_cd_m2, "cd/m²"));
  row(tb, "a " + fmt(p.change * 100) + " % change", fmt(p.change_jnd) + " JND: " + (p.change_visible ? "visible" : "invisible"));
}

function onPointer(e) {
  const img = $("frame");
  const rect = img.getBoundingClientRect();
  if (!state.width || rect.width === 0) return;
  const fx = (e.clientX - rect.left) / rect.width;
  const fy = (e.clientY - rect.top) / rect.height;
  if (fx < 0 || fy < 0 || fx >= 1 || fy >= 1) return;
  pointer = { x: Math.floor(fx * state.width), y: Math.floor(fy * state.height) };
  pixels.kick();
}

function setSplit() {
  const on = $("split").checked;
  for (const id of ["exposure", "divider", "label-a", "label-b"]) $(id).hidden = !on;
  $("split-at").disabled = !on;
  const at = Number($("split-at").value);
  $("exposure").style.clipPath = "inset(0 " + (100 - at) + "% 0 0)";
  $("divider").style.left = at + "%";
}

function setTimecourse() {
  const on = $("timecourse").checked;
  $("t").disabled = !on;
  $("play").disabled = !on;
  if (!on) stop();
}

function tick(now) {
  if (!state.playing) return;
  const dt = state.lastTick ? (now - state.lastTick) / 1000 : 0;
  state.lastTick = now;
  const t = Math.min(Number($("t-max").value), Number($("t").value) + dt * Number($("speed").value));
  $("t").value = String(t);
  if (t >= Number($("t-max").value)) stop();
  refresh();
}

function play() {
  if (Number($("t").value) >= Number($("t-max").value)) $("t").value = "0";
  state.playing = true;
  state.lastTick = 0;
  $("play").textContent = "pause";
  requestAnimationFrame(tick);
}

function stop() {
  const was = state.playing;
  state.playing = false;
  $("play").textContent = "play";
  if (was) reports.kick();
}

function preset(name) {
  const f = FIG12[name];
  $("timecourse").checked = true;
  $("from").value = String(f.from);
  $("level").value = String(Math.log10(f.to));
  $("t-max").value = String(f.tMax);
  $("t").max = String(f.tMax);
  $("t").value = "0";
  $("speed").value = String(f.speed);
  setTimecourse();
  play();
}

function init() {
  for (const id of ["level", "display-max", "fov", "acuity", "glare", "adaptation", "from", "t", "timecourse"]) {
    $(id).addEventListener("input", () => {
      if (id === "timecourse") setTimecourse();
      refresh();
    });
  }
  $("t-max").addEventListener("input", () => {
    $("t").max = $("t-max").value;
  });
  $("change").addEventListener("input", () => pixels.kick());
  $("split").addEventListener("input", () => {
    setSplit();
    refresh();
  });
  $("split-at").addEventListener("input", setSplit);
  $("native").addEventListener("click", () => {
    if (state.nativeLevel !== null) $("level").value = String(state.nativeLevel);
    refresh();
  });
  $("play").addEventListener("click", () => (state.playing ? stop() : play()));
  $("fig12a").addEventListener("click", () => preset("fig12a"));
  $("fig12b").addEventListener("click", () => preset("fig12b"));
  $("stage").addEventListener("mousemove", onPointer);
  window.addEventListener("resize", () => frames.kick());
  setSplit();
  setTimecourse();
  // The first report gives the image's size and level; it then asks for the first frame.
  reports.kick();
}

init();
