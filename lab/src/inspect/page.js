// activesense inspection page (paper §3.5). Written for this repository; no dependencies.
// Reads the trajectory embedded in <script id="trajectory"> (format 2, see
// docs/ARCHITECTURE.md) and draws the state the learnt policy saw at the selected step.
"use strict";
window.addEventListener("error", function (e) {
  document.getElementById("errors").textContent = "JavaScript error: " + e.message;
});
(function () {
  var T = JSON.parse(document.getElementById("trajectory").textContent);
  var H = T.inspection;
  var G = H.grid;
  var SIDE = H.belief_side;
  var PLANE = SIDE * SIDE;
  var K = G.rot_bins;
  var N = T.steps.length;
  var SCANS = 4, PIXELS = 20, HIST = 8;
  var ACTION_NAMES = ["rotate-left", "rotate-right", "measure"];
  var ACTION_KEYS = ["RotateLeft", "RotateRight", "Measure"];

  var el = function (id) { return document.getElementById(id); };
  var stepInput = el("step"), channelInput = el("channel"), gbpInput = el("gbp");
  stepInput.max = String(N - 1);
  channelInput.max = String(K - 1);
  channelInput.disabled = K < 2;

  // --- colour maps -------------------------------------------------------------------
  // Viridis (belief), sampled at 9 points and interpolated linearly.
  var VIRIDIS = [[68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
    [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37]];
  // Guided-back-propagation overlay: transparent dark red to yellow-white ("hot").
  var HOT = [[60, 0, 0], [180, 20, 0], [240, 90, 0], [255, 190, 20], [255, 255, 200]];
  function ramp(map, v) {
    v = Math.max(0, Math.min(1, v));
    var x = v * (map.length - 1), i = Math.min(map.length - 2, Math.floor(x)), f = x - i;
    var a = map[i], b = map[i + 1];
    return [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2])];
  }
  function rgb(c, alpha) {
    var s = Math.round(c[0]) + "," + Math.round(c[1]) + "," + Math.round(c[2]);
    return alpha === undefined ? "rgb(" + s + ")" : "rgba(" + s + "," + alpha.toFixed(3) + ")";
  }

  // --- state -------------------------------------------------------------------------
  function current() {
    return {
      t: Number(stepInput.value),
      k: Number(channelInput.value),
      gbp: gbpInput.checked
    };
  }

  // --- room --------------------------------------------------------------------------
  function roomFrame(canvas) {
    var lo = [Infinity, Infinity], hi = [-Infinity, -Infinity];
    T.plan.vertices.forEach(function (v) {
      lo[0] = Math.min(lo[0], v[0]); lo[1] = Math.min(lo[1], v[1]);
      hi[0] = Math.max(hi[0], v[0]); hi[1] = Math.max(hi[1], v[1]);
    });
    var m = 18, s = Math.min((canvas.width - 2 * m) / (hi[0] - lo[0]), (canvas.height - 2 * m) / (hi[1] - lo[1]));
    // centred in the canvas, y up
    var ox = (canvas.width - (hi[0] - lo[0]) * s) / 2, oy = (canvas.height - (hi[1] - lo[1]) * s) / 2;
    return function (x, y) { return [ox + (x - lo[0]) * s, canvas.height - oy - (y - lo[1]) * s]; };
  }
  function poly(ctx, pts) {
    ctx.beginPath();
    pts.forEach(function (p, i) { if (i === 0) ctx.moveTo(p[0], p[1]); else ctx.lineTo(p[0], p[1]); });
    ctx.closePath();
  }
  // A plan's rings (the outline, then its columns): `rings` holds each ring's end index,
  // absent for a plan of one ring. Wall i runs from vertex i to the next of its ring.
  function ringEnds(plan) {
    return plan.rings && plan.rings.length ? plan.rings : [plan.vertices.length];
  }
  function nextOf(plan, i) {
    var ends = ringEnds(plan), s = 0;
    for (var k = 0; k < ends.length; k++) {
      if (i < ends[k]) return i + 1 < ends[k] ? i + 1 : s;
      s = ends[k];
    }
    return 0;
  }
  function planPath(ctx, plan, P) {
    var s = 0;
    ctx.beginPath();
    ringEnds(plan).forEach(function (e) {
      plan.vertices.slice(s, e).forEach(function (v, i) {
        var p = P(v[0], v[1]);
        if (i === 0) ctx.moveTo(p[0], p[1]); else ctx.lineTo(p[0], p[1]);
      });
      ctx.closePath();
      s = e;
    });
  }
  // Door openings (`doors`: the door walls' indices, added by the page's writer; the
  // plan's 64-bit `openings` mask does not fit a JavaScript number), drawn as a dashed gap.
  function drawDoors(ctx, plan, P) {
    (plan.doors || []).forEach(function (i) {
      var a = plan.vertices[i], b = plan.vertices[nextOf(plan, i)];
      var p0 = P(a[0], a[1]), p1 = P(b[0], b[1]);
      ctx.strokeStyle = "#ffffff"; ctx.lineWidth = 4; ctx.setLineDash([]);
      ctx.beginPath(); ctx.moveTo(p0[0], p0[1]); ctx.lineTo(p1[0], p1[1]); ctx.stroke();
      ctx.strokeStyle = "#222"; ctx.lineWidth = 1; ctx.setLineDash([4, 3]);
      ctx.beginPath(); ctx.moveTo(p0[0], p0[1]); ctx.lineTo(p1[0], p1[1]); ctx.stroke();
      ctx.setLineDash([]);
    });
  }
  function drawPose(ctx, P, pose, colour, r) {
    var c = P(pose.x, pose.y);
    ctx.fillStyle = colour; ctx.strokeStyle = colour; ctx.lineWidth = 2;
    ctx.beginPath(); ctx.arc(c[0], c[1], r, 0, 2 * Math.PI); ctx.fill();
    ctx.beginPath(); ctx.moveTo(c[0], c[1]);
    ctx.lineTo(c[0] + 3 * r * Math.cos(pose.theta), c[1] - 3 * r * Math.sin(pose.theta)); ctx.stroke();
  }
  function drawRoom(s) {
    var cv = el("room"), ctx = cv.getContext("2d");
    var P = roomFrame(cv);
    ctx.clearRect(0, 0, cv.width, cv.height);
    ctx.fillStyle = "#f3f3f3";
    planPath(ctx, T.plan, P);
    ctx.fill("evenodd"); ctx.strokeStyle = "#222"; ctx.lineWidth = 2; ctx.stroke();
    drawDoors(ctx, T.plan, P);
    // the site: what stands in the room that the plan does not draw (--site), in violet
    var site = T.site;
    if (site) {
      ctx.fillStyle = "rgba(131,56,236,0.25)"; ctx.strokeStyle = "#8338ec"; ctx.lineWidth = 1.5;
      (site.obstacles || []).forEach(function (o) {
        poly(ctx, o.corners.map(function (v) { return P(v[0], v[1]); }));
        ctx.fill(); ctx.stroke();
      });
      var wv = site.as_built.vertices;
      (site.openings || []).forEach(function (o) {
        var a0 = wv[o.wall], b0 = wv[nextOf(site.as_built, o.wall)];
        var p0 = P(a0[0] + (b0[0] - a0[0]) * o.from, a0[1] + (b0[1] - a0[1]) * o.from);
        var p1 = P(a0[0] + (b0[0] - a0[0]) * o.to, a0[1] + (b0[1] - a0[1]) * o.to);
        ctx.setLineDash(o.depth_behind === null || o.depth_behind === undefined ? [3, 3] : []);
        ctx.lineWidth = 3; ctx.beginPath(); ctx.moveTo(p0[0], p0[1]); ctx.lineTo(p1[0], p1[1]); ctx.stroke();
      });
      ctx.setLineDash([]);
    }
    // visual centre and placement disc
    var vc = P(T.placement.visual_centre[0], T.placement.visual_centre[1]);
    var r = P(T.placement.visual_centre[0] + T.placement.radius, T.placement.visual_centre[1])[0] - vc[0];
    ctx.setLineDash([4, 4]); ctx.strokeStyle = "#999"; ctx.lineWidth = 1;
    ctx.beginPath(); ctx.arc(vc[0], vc[1], r, 0, 2 * Math.PI); ctx.stroke(); ctx.setLineDash([]);
    // beams measured before this decision
    var a = P(T.truth.x, T.truth.y);
    for (var i = 0; i < s.t; i++) {
      var st = T.steps[i];
      if (st.action !== "Measure" || st.range === null || st.range === undefined) continue;
      var b = P(T.truth.x + st.range * Math.cos(st.world_bearing), T.truth.y + st.range * Math.sin(st.world_bearing));
      ctx.strokeStyle = st.range_kind === "outlier" ? "#d08000"
        : (st.range_kind === "clutter" || st.range_kind === "behind") ? "#8338ec" : "#1565c0";
      ctx.lineWidth = 1.2;
      ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.stroke();
      ctx.fillStyle = ctx.strokeStyle; ctx.beginPath(); ctx.arc(b[0], b[1], 2.5, 0, 2 * Math.PI); ctx.fill();
    }
    // the beam direction now (before action t), dashed
    var wb = s.t > 0 ? T.steps[s.t - 1].world_bearing : T.truth.theta;
    var far = P(T.truth.x + 1e3 * Math.cos(wb), T.truth.y + 1e3 * Math.sin(wb));
    ctx.save(); ctx.beginPath(); ctx.rect(0, 0, cv.width, cv.height); ctx.clip();
    ctx.setLineDash([2, 3]); ctx.strokeStyle = "#c62828"; ctx.lineWidth = 1;
    ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(far[0], far[1]); ctx.stroke(); ctx.restore();
    ctx.setLineDash([]);
    drawPose(ctx, P, T.truth, "#2e7d32", 5);
    var est = s.t > 0 ? T.steps[s.t - 1].argmax : null;
    if (est) drawPose(ctx, P, est, "#8e24aa", 4);
    // The last frame also shows the episode's answer: the refined pose, which can sit far
    // from the belief argmax (the refinement fits the readings, the argmax is a grid cell).
    var o = T.outcome, fin = s.t === N - 1 && o.refined ? o.refined.pose : null;
    if (fin) drawPose(ctx, P, fin, "#ef6c00", 4);
    el("room-legend").innerHTML =
      '<span class="sw" style="background:#2e7d32"></span>instrument (truth)' +
      '<span class="sw" style="background:#8e24aa"></span>estimate (belief argmax' + (est ? "" : ": none yet") + ')' +
      (fin ? '<span class="sw" style="background:#ef6c00"></span>final answer (refined' +
        (o.pose_error !== null && o.pose_error !== undefined ? ", error " + o.pose_error.toFixed(4) + " m" : "") + ')' : "") +
      '<span class="sw" style="background:#1565c0"></span>ranges' +
      '<span class="sw" style="background:#d08000"></span>outliers' +
      (site ? '<span class="sw" style="background:#8338ec"></span>site, not on the plan (' + site.level + '), and readings off it' : "") +
      '<span class="sw" style="background:#c62828"></span>beam now' +
      '<span class="sw" style="background:#999"></span>placement disc';
  }

  // --- heat map ----------------------------------------------------------------------
  function gbpScale(ins) {
    // The overlay shows the positive part of the guided map, normalised by its largest
    // value over all channels of this step.
    var m = 0;
    for (var i = 0; i < ins.gbp_belief.length; i++) if (ins.gbp_belief[i] > m) m = ins.gbp_belief[i];
    return m;
  }
  function drawHeat(s) {
    var cv = el("heat"), ctx = cv.getContext("2d");
    var ins = T.steps[s.t].inspect, cell = cv.width / SIDE, base = s.k * PLANE;
    var gmax = gbpScale(ins);
    ctx.clearRect(0, 0, cv.width, cv.height);
    for (var y = 0; y < SIDE; y++) {
      for (var x = 0; x < SIDE; x++) {
        var v = ins.belief[base + y * SIDE + x];
        var px = x * cell, py = cv.height - (y + 1) * cell; // row 0 at the bottom (y up)
        if (s.gbp) {
          var g = Math.round(40 + 120 * v);
          ctx.fillStyle = "rgb(" + g + "," + g + "," + g + ")";
          ctx.fillRect(px, py, cell + 0.5, cell + 0.5);
          var w = gmax > 0 ? Math.max(0, ins.gbp_belief[base + y * SIDE + x]) / gmax : 0;
          if (w > 0) { ctx.fillStyle = rgb(ramp(HOT, w), Math.min(1, 0.25 + w)); ctx.fillRect(px, py, cell + 0.5, cell + 0.5); }
        } else {
          ctx.fillStyle = rgb(ramp(VIRIDIS, v));
          ctx.fillRect(px, py, cell + 0.5, cell + 0.5);
        }
      }
    }
    // grid extent (cells beyond nx, ny are padding) and the room outline in cell units
    var C = function (mx, my) {
      return [(mx - G.origin[0]) / G.cell[0] * cell, cv.height - (my - G.origin[1]) / G.cell[1] * cell];
    };
    planPath(ctx, T.plan, C);
    ctx.strokeStyle = "rgba(0,0,0,0.8)"; ctx.lineWidth = 3.5; ctx.stroke();
    ctx.strokeStyle = "rgba(255,255,255,0.95)"; ctx.lineWidth = 1.5; ctx.stroke();
    ctx.strokeStyle = "rgba(255,255,255,0.35)"; ctx.lineWidth = 1;
    ctx.strokeRect(0, cv.height - G.ny * cell, G.nx * cell, G.ny * cell);
    // truth (cross) and visual centre (ring)
    var tc = C(T.truth.x, T.truth.y);
    ctx.strokeStyle = "#ff4081"; ctx.lineWidth = 2; ctx.beginPath();
    ctx.moveTo(tc[0] - 5, tc[1] - 5); ctx.lineTo(tc[0] + 5, tc[1] + 5);
    ctx.moveTo(tc[0] + 5, tc[1] - 5); ctx.lineTo(tc[0] - 5, tc[1] + 5); ctx.stroke();
    var vc = C(T.placement.visual_centre[0], T.placement.visual_centre[1]);
    ctx.strokeStyle = "#00e5ff"; ctx.beginPath(); ctx.arc(vc[0], vc[1], 5, 0, 2 * Math.PI); ctx.stroke();
    var heading = K > 1 ? " (heading " + (s.k * 360 / K).toFixed(0) + "°)" : " (heading known)";
    el("heat-caption").textContent = (s.gbp
      ? "guided back-propagation of '" + ACTION_NAMES[actionIndex(T.steps[s.t].action)] + "', channel " + s.k
      : "belief map, channel " + s.k) + heading;
    drawScale(s, gmax);
  }
  function drawScale(s, gmax) {
    var cv = el("scale"), ctx = cv.getContext("2d");
    ctx.clearRect(0, 0, cv.width, cv.height);
    var w = cv.width - 20;
    for (var i = 0; i < w; i++) {
      var v = i / (w - 1);
      ctx.fillStyle = s.gbp ? rgb(ramp(HOT, v), Math.min(1, 0.25 + v)) : rgb(ramp(VIRIDIS, v));
      ctx.fillRect(10 + i, 2, 1.5, 14);
    }
    ctx.fillStyle = "#222"; ctx.font = "11px sans-serif"; ctx.textBaseline = "top";
    ctx.textAlign = "left";
    ctx.fillText("0", 10, 19);
    ctx.textAlign = "right";
    ctx.fillText(s.gbp ? "max " + gmax.toExponential(2) + " (positive part, this step)" : "1 = peak probability", cv.width - 10, 19);
  }
  function actionIndex(a) { return ACTION_KEYS.indexOf(a); }

  // --- scans and action history ------------------------------------------------------
  function drawScans(s) {
    var cv = el("scans"), ctx = cv.getContext("2d");
    var ins = T.steps[s.t].inspect, side = ins.side, g = ins.gbp_side;
    var gmax = 0;
    for (var i = 0; i < g.length; i++) if (g[i] > gmax) gmax = g[i];
    ctx.clearRect(0, 0, cv.width, cv.height);
    ctx.font = "11px sans-serif"; ctx.textBaseline = "middle"; ctx.fillStyle = "#222";
    var cw = 13, x0 = 52;
    function cellAt(x, y, on, gv, size) {
      ctx.fillStyle = on ? "#263238" : "#cfd8dc";
      ctx.fillRect(x, y, size - 1, size - 1);
      if (s.gbp && gmax > 0 && gv > 0) {
        // the overlay as an inset square, so the pixel's own state stays visible as a frame
        ctx.fillStyle = rgb(ramp(HOT, gv / gmax));
        ctx.fillRect(x + 2.5, y + 2.5, size - 6, size - 6);
      }
    }
    for (var r = 0; r < SCANS; r++) {
      var y = 6 + r * (cw + 3);
      ctx.fillStyle = "#222"; ctx.textAlign = "right";
      ctx.fillText(r === 0 ? "now" : "t-" + r, x0 - 6, y + cw / 2);
      for (var p = 0; p < PIXELS; p++) {
        var k = r * PIXELS + p;
        // pixel 0 is the clockwise edge: drawn on the right, as the view reads
        cellAt(x0 + (PIXELS - 1 - p) * cw, y, side[k] > 0.5, g[k], cw);
      }
    }
    var hy = 6 + SCANS * (cw + 3) + 14;
    ctx.fillStyle = "#222"; ctx.textAlign = "left";
    ctx.fillText("last actions (latest left):", 4, hy);
    var ab = SCANS * PIXELS;
    for (var j = 0; j < 3; j++) {
      var yy = hy + 10 + j * (cw + 3);
      ctx.fillStyle = "#222"; ctx.textAlign = "right";
      ctx.fillText(ACTION_NAMES[j], x0 + 24, yy + cw / 2);
      for (var a = 0; a < HIST; a++) {
        cellAt(x0 + 30 + a * cw, yy, side[ab + a * 3 + j] > 0.5, g[ab + a * 3 + j], cw);
      }
    }
    var rest = ab + HIST * 3;
    var ry = hy + 10 + 3 * (cw + 3) + 12;
    ctx.fillStyle = "#222"; ctx.textAlign = "left";
    var names = ["cos β", "sin β", "step/100", "meas/10"];
    for (var q = 0; q < 4; q++) {
      var txt = names[q] + " " + side[rest + q].toFixed(2) + (s.gbp ? " (gbp " + g[rest + q].toExponential(1) + ")" : "");
      ctx.fillText(txt, 4 + (q % 2) * 165, ry + Math.floor(q / 2) * 16);
    }
    el("side-note").textContent = s.gbp
      ? "overlay: positive part of the guided map over the side features, normalised by its largest value (" + gmax.toExponential(2) + ")"
      : "dark = wall junction seen in that pixel / action taken";
  }

  // --- action probabilities and value ------------------------------------------------
  function drawProbs(s) {
    var cv = el("probs"), ctx = cv.getContext("2d");
    var st = T.steps[s.t], ins = st.inspect, chosen = actionIndex(st.action);
    ctx.clearRect(0, 0, cv.width, cv.height);
    ctx.font = "12px sans-serif"; ctx.textBaseline = "middle";
    for (var i = 0; i < 3; i++) {
      var y = 12 + i * 40, w = (cv.width - 150) * ins.probs[i];
      ctx.fillStyle = "#222"; ctx.textAlign = "right";
      ctx.fillText(ACTION_NAMES[i], 92, y + 12);
      ctx.fillStyle = i === chosen ? "#ef6c00" : "#90a4ae";
      ctx.fillRect(100, y, Math.max(1, w), 24);
      ctx.fillStyle = "#222"; ctx.textAlign = "left";
      ctx.fillText(ins.probs[i].toFixed(3), 104 + w, y + 12);
    }
    ctx.textAlign = "left";
    ctx.fillText("value V(s) = " + ins.value.toFixed(3), 10, 12 + 3 * 40 + 14);
    ctx.fillText("logits " + ins.logits.map(function (l) { return l.toFixed(2); }).join(", "), 10, 12 + 3 * 40 + 34);
    var r = st.range !== null && st.range !== undefined ? ", range " + st.range.toFixed(3) + " m" : (st.action === "Measure" ? ", no return" : "");
    el("decision").textContent = "chose " + ACTION_NAMES[chosen] + r + "; cost so far " +
      st.cost.toFixed(3) + "; belief entropy after it " + st.entropy.toFixed(2) + " nats";
  }

  // --- wiring ------------------------------------------------------------------------
  function render() {
    var s = current();
    el("step-label").textContent = "step " + s.t + " / " + (N - 1);
    el("channel-label").textContent = "channel " + s.k + " / " + (K - 1);
    drawRoom(s);
    drawHeat(s);
    drawScans(s);
    drawProbs(s);
    document.body.setAttribute("data-step", String(s.t));
    document.body.setAttribute("data-channel", String(s.k));
    document.body.setAttribute("data-gbp", s.gbp ? "on" : "off");
  }
  function nudge(input, d) {
    var v = Math.max(Number(input.min), Math.min(Number(input.max), Number(input.value) + d));
    if (v !== Number(input.value)) { input.value = String(v); render(); }
  }
  stepInput.addEventListener("input", render);
  channelInput.addEventListener("input", render);
  gbpInput.addEventListener("change", render);
  document.addEventListener("keydown", function (e) {
    if (e.target === stepInput || e.target === channelInput) return; // the slider handles its own keys
    if (e.key === "ArrowRight") { nudge(stepInput, 1); e.preventDefault(); }
    else if (e.key === "ArrowLeft") { nudge(stepInput, -1); e.preventDefault(); }
    else if (e.key === "ArrowUp") { nudge(channelInput, 1); e.preventDefault(); }
    else if (e.key === "ArrowDown") { nudge(channelInput, -1); e.preventDefault(); }
    else if (e.key === "Home") { nudge(stepInput, -N); e.preventDefault(); }
    else if (e.key === "End") { nudge(stepInput, N); e.preventDefault(); }
    else if (e.key === "g") { gbpInput.checked = !gbpInput.checked; render(); }
  });
  var o = T.outcome;
  el("summary").textContent = "plan " + T.spec.plan_seed + ", episode seed " + T.spec.episode_seed +
    ", K = " + K + ", policy " + H.policy + "; " + N + " actions (" + T.summary.measurements +
    " measurements, " + T.summary.rotations + " rotations), cost " + T.summary.cost.toFixed(3) +
    ", ended: " + T.end + ", recognised: " + (o.recognised ? "yes" : "no") +
    (o.pose_error !== null && o.pose_error !== undefined ? ", pose error " + o.pose_error.toFixed(4) + " m" : "") +
    ". Step t shows the state the policy decided on before action t.";
  render();
})();
