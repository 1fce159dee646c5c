"""The live view's page (served by pipeline.live.view): one self-contained HTML file, no external
resources, plain JavaScript that polls ``state.json`` and ``frame.jpg`` and draws the angle
traces on a canvas."""

PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>wristtrack live</title>
<style>
  body { font-family: sans-serif; margin: 12px; background: #fafafa; color: #222; }
  h1 { font-size: 18px; margin: 0 0 8px 0; }
  #bar { font-size: 14px; margin-bottom: 8px; }
  #status { font-weight: bold; padding: 2px 8px; border-radius: 4px; background: #ccc; }
  #status.tracking { background: #2ca02c; color: #fff; }
  #status.coasting { background: #ff9f1c; }
  #status.lost { background: #d62728; color: #fff; }
  #status.ended { background: #555; color: #fff; }
  .row { display: flex; flex-wrap: wrap; gap: 12px; align-items: flex-start; }
  #video { width: 640px; max-width: 100%; background: #000; min-height: 120px; }
  #traces { background: #fff; border: 1px solid #ccc; }
  table { border-collapse: collapse; font-size: 14px; margin-top: 8px; }
  td, th { border: 1px solid #ccc; padding: 2px 8px; text-align: right; }
  th { background: #eee; }
  .dev { color: #d62728; } .flex { color: #1f77b4; } .pro { color: #2ca02c; }
</style>
</head>
<body>
<h1>wristtrack live <span id="source"></span></h1>
<div id="bar">
  <span id="status">connecting</span>
  frame <span id="frame">-</span> &middot; t <span id="time">-</span> s &middot;
  <span id="fps">-</span> fps &middot; latency <span id="latency">-</span> ms
  (p95 <span id="p95">-</span>) &middot; dropped <span id="dropped">0</span> &middot;
  markers <span id="markers">-</span>/6
</div>
<div class="row">
  <img id="video" alt="overlay video">
  <div>
    <canvas id="traces" width="560" height="360"></canvas>
    <table>
      <tr><th>range of motion so far</th><th>min (deg)</th><th>max (deg)</th>
          <th>range (deg)</th></tr>
      <tr><th class="dev">deviation (ulnar +)</th><td id="dev-min">-</td>
          <td id="dev-max">-</td><td id="dev-range">-</td></tr>
      <tr><th class="flex">flexion (+)</th><td id="flex-min">-</td>
          <td id="flex-max">-</td><td id="flex-range">-</td></tr>
      <tr><th class="pro">pronation (+)</th><td id="pro-min">-</td>
          <td id="pro-max">-</td><td id="pro-range">-</td></tr>
    </table>
  </div>
</div>
<script>
"use strict";
var WINDOW_S = 10;  // seconds of trace shown
var COLOURS = ["#d62728", "#1f77b4", "#2ca02c"];
var NAMES = ["deviation", "flexion", "pronation"];
var KEYS = ["dev", "flex", "pro"];
var samples = [];  // [t, deviation, flexion, pronation]
var next = 0, version = -1, failures = 0, loading = false;

function text(id, value) { document.getElementById(id).textContent = value; }
function fixed(x, n) { return (x === null || x === undefined) ? "-" : x.toFixed(n); }

function draw() {
  var c = document.getElementById("traces"), g = c.getContext("2d");
  var W = c.width, H = c.height, L = 44, R = 8, T = 22, B = 26;
  g.fillStyle = "#fff"; g.fillRect(0, 0, W, H);
  var tEnd = samples.length ? samples[samples.length - 1][0] : WINDOW_S;
  var tStart = Math.max(samples.length ? samples[0][0] : 0, tEnd - WINDOW_S);
  var lo = -30, hi = 30, i, k;
  for (i = 0; i < samples.length; i++) {
    if (samples[i][0] < tStart) continue;
    for (k = 1; k < 4; k++) {
      var v = samples[i][k];
      if (v !== null) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
    }
  }
  lo = Math.floor(lo / 10) * 10; hi = Math.ceil(hi / 10) * 10;
  var span = Math.max(tEnd - tStart, 1e-6);
  function x(t) { return L + (W - L - R) * (t - tStart) / span; }
  function y(v) { return T + (H - T - B) * (hi - v) / (hi - lo); }
  g.strokeStyle = "#ddd"; g.fillStyle = "#555"; g.font = "11px sans-serif"; g.lineWidth = 1;
  for (var a = lo; a <= hi; a += (hi - lo > 120 ? 30 : 10)) {
    g.beginPath(); g.moveTo(L, y(a)); g.lineTo(W - R, y(a)); g.stroke();
    g.fillText(a + "\\u00b0", 4, y(a) + 4);
  }
  g.fillText("t = " + tStart.toFixed(1) + " s", L, H - 8);
  g.fillText(tEnd.toFixed(1) + " s", W - R - 40, H - 8);
  for (k = 1; k < 4; k++) {
    g.strokeStyle = COLOURS[k - 1]; g.lineWidth = 2; g.beginPath();
    var pen = false;
    for (i = 0; i < samples.length; i++) {
      var s = samples[i];
      if (s[0] < tStart || s[k] === null) { pen = false; continue; }
      if (pen) g.lineTo(x(s[0]), y(s[k])); else g.moveTo(x(s[0]), y(s[k]));
      pen = true;
    }
    g.stroke();
    g.fillStyle = COLOURS[k - 1]; g.fillText(NAMES[k - 1], L + 8 + (k - 1) * 90, 14);
  }
}

function show(state) {
  var st = document.getElementById("status");
  var status = state.finished ? "ended (" + state.ended_by + ")" : state.status;
  st.textContent = status;
  st.className = state.finished ? "ended" : state.status;
  text("source", state.source ? "\\u2014 " + state.source : "");
  text("frame", state.frame === undefined ? "-" : state.frame);
  text("time", fixed(state.timestamp, 2));
  text("fps", fixed(state.fps, 1));
  text("latency", fixed(state.latency_ms, 1));
  text("p95", fixed(state.latency_p95_ms, 1));
  text("dropped", state.dropped === undefined ? 0 : state.dropped);
  text("markers", state.markers === undefined ? "-" : state.markers);
  for (var k = 0; k < 3; k++) {
    var r = state.rom[NAMES[k]];
    text(KEYS[k] + "-min", r ? r.min_deg.toFixed(1) : "-");
    text(KEYS[k] + "-max", r ? r.max_deg.toFixed(1) : "-");
    text(KEYS[k] + "-range", r ? r.range_deg.toFixed(1) : "-");
  }
  samples = samples.concat(state.traces);
  var keep = samples.length ? samples[samples.length - 1][0] - 2 * WINDOW_S : 0;
  while (samples.length && samples[0][0] < keep) samples.shift();
  next = state.next;
  draw();
  if (state.version !== version && !loading) {
    version = state.version; loading = true;
    var img = document.getElementById("video");
    img.onload = img.onerror = function () { loading = false; };
    img.src = "frame.jpg?v=" + version;
  }
}

function poll() {
  var req = new XMLHttpRequest();
  req.open("GET", "state.json?since=" + next);
  req.timeout = 2000;
  req.onload = function () {
    failures = 0;
    var state = JSON.parse(req.responseText);
    show(state);
    if (!state.finished) setTimeout(poll, 100);
  };
  req.onerror = req.ontimeout = function () {
    failures += 1;
    var st = document.getElementById("status");
    st.textContent = "disconnected: the run has ended"; st.className = "ended";
    if (failures < 5) setTimeout(poll, 1000);
  };
  req.send();
}
draw();
poll();
</script>
</body>
</html>
"""
