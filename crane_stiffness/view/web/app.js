// The live view page: a Foxglove WebSocket client (subprotocol from config.json) drawing the derived channels of
// the live_view node on plain canvases. No library: JSON channels, binary messageData frames (opcode 1:
// u32 subscription id, u64 log time, payload).
'use strict';
// The kind of run (config.json's run, or six_axis once a 6×6 fit arrives) decides the layout, once: a six-axis run
// leads with the 6×6 and shows no one-axis verdict (the one-axis fit does not apply to its multi-axis load).
const CHANNELS = ['xy', 'fit_lines', 'prediction', 'estimate', 'status', 'wires', 'scene', 'stiffness6'];
const state = { messages: 0, lastCount: 0, data: {}, dirty: new Set(), drawnAt: 0, run: null, k6Row: 1 };
// The boxes of the text drawn on each canvas, in its pixels ({text, left, top, width, height}), as the drawing code
// placed it: what a test reads to check that no two texts of the page overlap (the DOM's text it reads itself).
window.__textBoxes = { xy: [], scene: [], kint: [], k6int: [] };
const WIRE_LABEL = /^wire_\d/;
// What each channel changes on the page: only that part is drawn again (the rest keeps its pixels and DOM).
const PART = { xy: 'plot', fit_lines: 'plot', prediction: 'plot', estimate: 'text', status: 'text', wires: 'wires',
  scene: 'scene', stiffness6: 'stiffness6' };
// At most this often [ms]: messages come at 70-80/s; a person reads the page at a few updates a second.
const DRAW_PERIOD_MS = 100;
// Status levels (crane_stiffness.status), each a CSS class level-<n>: -1 WAITING (not begun), 0 OK, 1 WARN, 2 ERROR,
// 3 STALE (data that was flowing stopped). The status channel names them (level_name).

function fmt(v, digits) { return v === null || v === undefined ? '–' : Number(v).toPrecision(digits); }
// 4 significant digits, compact: 7.169e4, -1.790e4, 0.000
function compact(v) {
  if (v === null || v === undefined) return '–';
  const a = Math.abs(v);
  return (a !== 0 && (a >= 1e4 || a < 1e-2) ? Number(v).toExponential(3).replace('e+', 'e') : Number(v).toPrecision(4));
}
// measured / tangent - 1 as a colour: blue (−2 % and below), white (0), red (+2 % and above)
const SATURATION = 0.02;
function diverging(rel) {
  const t = Math.max(-1, Math.min(1, rel / SATURATION));
  const fade = Math.round(255 * (1 - Math.abs(t)));
  return t >= 0 ? `rgb(255,${fade},${fade})` : `rgb(${fade},${fade},255)`;
}

function setRun(run) {
  // The layout for the kind of run, set before the page is shown (and once more only if a six-axis fit arrives on
  // a run the rig did not say was six-axis).
  if (state.run === run) return;
  state.run = run;
  document.body.className = run === 'six_axis' ? 'six-axis' : 'one-axis';
  document.body.dataset.run = run;
  document.getElementById('main').hidden = false;
  state.dirty.add('plot'); state.dirty.add('scene'); state.dirty.add('stiffness6'); state.dirty.add('text');
}

function buildTables() {
  // Every table in its final shape from the first frame, each cell saying '–' until its data come.
  const axes = ['fx', 'fy', 'fz', 'mx', 'my', 'mz'], disp = ['u_x', 'u_y', 'u_z', 'θ_x', 'θ_y', 'θ_z'];
  document.getElementById('stiffness6').innerHTML = '<tr><th></th>' + disp.map((d) => `<th>${d}</th>`).join('') +
    '</tr>' + axes.map((a) => `<tr><th>${a}</th>` + disp.map(() => '<td class="k6">–</td>').join('') + '</tr>')
      .join('');
  const select = document.getElementById('k6-row');
  select.innerHTML = axes.map((a, i) => `<option value="${i}">${a}</option>`).join('');
  select.value = String(state.k6Row);
  select.onchange = () => { state.k6Row = Number(select.value); state.dirty.add('stiffness6'); };
  document.getElementById('k6-row-table').innerHTML =
    '<tr><th>displacement</th><th>K measured</th><th>repeatability 95 %</th><th>U (95 %)</th><th>model tangent</th>' +
    '<th>measured / tangent − 1</th></tr>' +
    disp.map((d) => `<tr><td>${d}</td><td>–</td><td>–</td><td>–</td><td>–</td><td>–</td></tr>`).join('');
  document.getElementById('wires').innerHTML = '<tr><th>wire</th><th>tension</th><th>length</th></tr>' +
    [1, 2, 3, 4, 5, 6].map((i) => `<tr><td>wire_${i}</td><td>–</td><td>–</td></tr>`).join('');
}

// The token of the page's address (?token=..., as the live view prints it) goes with the WebSocket's: without it
// the page may only watch (on loopback), or not connect at all (a server on the lab network).
const TOKEN = new URLSearchParams(location.search).get('token');

function connect(config) {
  const query = TOKEN ? `/?token=${encodeURIComponent(TOKEN)}` : '/';
  const ws = new WebSocket(`ws://${location.hostname}:${config.ws_port}${query}`, [config.subprotocol]);
  ws.binaryType = 'arraybuffer';
  const bySubscription = {};
  let nextId = 1;
  ws.onopen = () => setConnection(0, 'connected');
  ws.onclose = () => {
    // off loopback the server refuses a page without the token: say where it comes from
    setConnection(2, TOKEN ? 'disconnected, retrying'
      : 'disconnected, retrying (open the address with ?token=… as the live view printed it)');
    setTimeout(() => connect(config), 1000);
  };
  ws.onmessage = (event) => {
    if (typeof event.data === 'string') {
      const msg = JSON.parse(event.data);
      if (msg.op === 'advertise') {
        const subscriptions = [];
        for (const ch of msg.channels) {
          const name = ch.topic.startsWith('/live_view/') ? ch.topic.slice('/live_view/'.length) : null;
          if (CHANNELS.includes(name)) {
            const id = nextId++;
            bySubscription[id] = name;
            subscriptions.push({ id, channelId: ch.id });
          }
        }
        if (subscriptions.length) ws.send(JSON.stringify({ op: 'subscribe', subscriptions }));
      }
      return;
    }
    const view = new DataView(event.data);
    if (view.getUint8(0) !== 1) return;
    const name = bySubscription[view.getUint32(1, true)];
    if (!name) return;
    state.data[name] = JSON.parse(new TextDecoder().decode(new Uint8Array(event.data, 13)));
    if (name === 'stiffness6' && state.data.stiffness6.fit) setRun('six_axis');
    state.messages++;
    state.dirty.add(PART[name]);
  };
}

function setConnection(level, text) {
  const el = document.getElementById('connection');
  el.className = `level-${level}`;
  el.textContent = text;
}

function axisOf() {
  // The fitted axis and its stiffness unit, as the estimator's status names them (N/m until it has said).
  const st = state.data.status;
  return { axis: st && st.axis ? st.axis : '', unit: st && st.unit ? st.unit : 'N/m' };
}

function updateText() {
  const est = state.data.estimate;
  const { axis, unit } = axisOf();
  document.getElementById('axis').textContent = axis ? `fitting ${axis}, k in ${unit}` : '';
  if (est) {
    for (const b of ['loading', 'unloading']) {
      const e = est[b];
      const k = document.getElementById(`k-${b}`);
      k.textContent = e.stiffness === null ? '–' : `${fmt(e.stiffness, 6)} ${unit}`;
      k.dataset.value = e.stiffness === null ? '' : String(e.stiffness);
      k.dataset.sampleStamp = e.sample_stamp === null ? '' : String(e.sample_stamp);
      document.getElementById(`ci-${b}`).textContent =
        e.ci95_low === null ? '–' : `${fmt(e.ci95_low, 6)} .. ${fmt(e.ci95_high, 6)}`;
      document.getElementById(`n-${b}`).textContent = e.n === null ? '–' : e.n;
    }
    const p = est.loading.prediction;
    document.getElementById('k-prediction').textContent = p === null ? '–' : `${fmt(p, 6)} ${unit}`;
    const rel = est.loading.relative_error;
    document.getElementById('rel-error').textContent = rel === null ? '' : `loading ${(100 * rel).toFixed(2)} %`;
    updateIntervals(est, unit);
  }
  const st = state.data.status;
  if (st) {
    const el = document.getElementById('status-level');
    el.className = `level-${st.level}`;
    el.textContent = st.level_name;
    el.dataset.level = st.level;
    document.getElementById('status').textContent =
      st.statuses.map((s) => `${s.name.split(': ').pop()}: ${s.level_name} ${s.message}`).join('\n');
  }
  const xy = state.data.xy;
  if (xy) {
    document.getElementById('segment').textContent =
      `segment ${xy.segment}, ${xy.pairs} pairs fitted, every ${xy.stride}. shown`;
  }
}

function updateWires() {
  // The rows are made once and their cells rewritten: no new DOM (and layout) for every message.
  const wires = state.data.wires;
  if (!wires) return;
  const table = document.getElementById('wires');
  if (table.rows.length !== wires.wires.length + 1) {  // (six, made at the start: another count is rebuilt)
    table.innerHTML = '<tr><th>wire</th><th>tension</th><th>length</th></tr>' +
      wires.wires.map(() => '<tr><td></td><td></td><td></td></tr>').join('');
  }
  wires.wires.forEach((w, i) => {
    const row = table.rows[i + 1], cells = row.cells;
    const cls = w.slack ? 'slack' : '';
    if (row.className !== cls) row.className = cls;
    cells[0].textContent = w.name;
    cells[1].dataset.value = w.tension;
    cells[1].textContent = w.slack ? 'slack' : fmt(w.tension, 5) + ' N';
    cells[2].textContent = `${fmt(w.length * 1000, 6)} mm`;
  });
}

// Text on a canvas, its box recorded (window.__textBoxes[canvas id]): align 'left'/'center'/'right' about x, the
// baseline at y; with `vertical`, turned by -90° about (x, y) (read upwards).
function canvasText(ctx, id, text, x, y, align = 'left', vertical = false) {
  const m = ctx.measureText(text);
  const w = m.width, up = m.actualBoundingBoxAscent, down = m.actualBoundingBoxDescent;
  const shift = align === 'center' ? w / 2 : align === 'right' ? w : 0;
  ctx.save();
  ctx.textAlign = 'left';
  if (vertical) {
    ctx.translate(x, y); ctx.rotate(-Math.PI / 2); ctx.fillText(text, -shift, 0); ctx.restore();
    window.__textBoxes[id].push({ text, left: x - up, top: y - w + shift, width: up + down, height: w });
    return;
  }
  ctx.fillText(text, x - shift, y);
  ctx.restore();
  window.__textBoxes[id].push({ text, left: x - shift, top: y - up, width: w, height: up + down });
}

function overlaps(a, b, gap = 0) {
  return a.left < b.left + b.width + gap && b.left < a.left + a.width + gap &&
    a.top < b.top + b.height + gap && b.top < a.top + a.height + gap;
}

// The intervals table under the plot: each branch's k, its repeatability (the fit's 95 % interval), its expanded
// uncertainty U (GUM, 95 %) and k ± U, E_n against the model; the model's prediction with its own U.
function updateIntervals(est, unit) {
  const set = (id, text, value) => {
    const el = document.getElementById(id);
    el.textContent = text;
    el.dataset.value = value === null || value === undefined ? '' : String(value);
  };
  for (const b of ['loading', 'unloading']) {
    const e = est[b];
    set(`ki-${b}`, e.stiffness === null ? '–' : `${fmt(e.stiffness, 6)} ${unit}`, e.stiffness);
    set(`rep-${b}`, e.ci95_low === null ? '–' : `${fmt(e.ci95_low, 6)} .. ${fmt(e.ci95_high, 6)}`,
      e.ci95_low === null ? null : `${e.ci95_low},${e.ci95_high}`);
    set(`U-${b}`, e.U === null ? '–' : `± ${fmt(e.U, 4)} (k = ${fmt(e.coverage_factor, 3)})`, e.U);
    set(`Uint-${b}`, e.U_low === null ? '–' : `${fmt(e.U_low, 6)} .. ${fmt(e.U_high, 6)}`,
      e.U_low === null ? null : `${e.U_low},${e.U_high}`);
    const en = document.getElementById(`En-${b}`);
    set(`En-${b}`, e.En === null ? '–' : `${e.En >= 0 ? '+' : '−'}${Math.abs(e.En).toFixed(2)}`, e.En);
    en.className = e.En === null ? '' : (Math.abs(e.En) > 1 ? 'en-far' : 'en-agree');
  }
  const p = est.loading.prediction, pu = est.loading.prediction_U;
  set('ki-model', p === null ? '–' : `${fmt(p, 6)} ${unit}`, p);
  set('U-model', pu === null ? '–' : `± ${fmt(pu, 4)}`, pu);
  set('Uint-model', p === null || pu === null ? '–' : `${fmt(p - pu, 6)} .. ${fmt(p + pu, 6)}`,
    p === null || pu === null ? null : `${p - pu},${p + pu}`);
  const l = est.loading;
  document.getElementById('calibration').textContent = l.U === null ? 'U: waiting for the estimator\'s status…' :
    (l.statistical_only ? 'U is statistical only: no calibration declared by the sensors (their calibration.* ' +
      'parameters), so it is the fit\'s alone.' :
      'U counts the fit and the sensors\' declared calibrations (load cell and LVDT certificates); |E_n| <= 1: ' +
      'the measurement agrees with the model within both U.');
  drawIntervals(est, unit);
}

// The intervals drawn on one scale: per branch a dot at k, a thick bar over its repeatability interval and a thin
// line with end ticks over k ± U; the model's prediction ± its U. The canvas says what it drew (in pixels) for tests.
function drawIntervals(est, unit) {
  const canvas = document.getElementById('kint');
  const ctx = canvas.getContext('2d');
  const W = canvas.width, H = canvas.height, m = { l: 90, r: 20, t: 10, b: 26 };
  ctx.clearRect(0, 0, W, H);
  window.__textBoxes.kint = [];
  ctx.font = '12px sans-serif';
  const p = est.loading.prediction, pu = est.loading.prediction_U;
  const rows = [['loading', '#1f77b4', est.loading], ['unloading', '#e07b00', est.unloading]]
    .filter(([, , e]) => e.stiffness !== null)
    .map(([name, color, e]) => ({ name, color, k: e.stiffness, rep: [e.ci95_low, e.ci95_high],
      u: e.U === null ? null : [e.U_low, e.U_high] }));
  if (p !== null) rows.push({ name: 'model', color: '#2a9d2a', k: p, rep: null, u: pu === null ? null : [p - pu, p + pu] });
  if (!rows.length) {
    ctx.fillStyle = '#333';
    canvasText(ctx, 'kint', 'waiting for an estimate…', W / 2, H / 2, 'center');
    canvas.dataset.drawn = '';
    return;
  }
  let [lo, hi] = [Infinity, -Infinity];
  for (const r of rows) for (const v of [r.k, ...(r.u || []), ...(r.rep || [])]) {
    if (v !== null) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
  }
  const pad = (hi - lo) * 0.08 || Math.abs(hi) * 1e-3 || 1;
  lo -= pad; hi += pad;
  const sx = (v) => m.l + (v - lo) / (hi - lo) * (W - m.l - m.r);
  const rowH = (H - m.t - m.b) / 3;
  ctx.strokeStyle = '#ccc'; ctx.lineWidth = 1;
  ctx.beginPath(); ctx.moveTo(m.l, H - m.b); ctx.lineTo(W - m.r, H - m.b); ctx.stroke();
  ctx.fillStyle = '#333';
  for (let i = 0; i <= 4; i++) {
    const v = lo + (hi - lo) * i / 4;
    canvasText(ctx, 'kint', fmt(v, 6), sx(v), H - 8, i === 0 ? 'left' : i === 4 ? 'right' : 'center');
  }
  const drawn = {};
  rows.forEach((r, i) => {
    const y = m.t + rowH * (i + 0.5);
    ctx.fillStyle = r.color;
    canvasText(ctx, 'kint', r.name, 6, y + 4);
    ctx.strokeStyle = r.color; ctx.fillStyle = r.color;
    const d = { k: r.k };
    if (r.u) {  // k ± U: a thin line with end ticks
      ctx.lineWidth = 1.5; ctx.beginPath();
      ctx.moveTo(sx(r.u[0]), y); ctx.lineTo(sx(r.u[1]), y);
      for (const v of r.u) { ctx.moveTo(sx(v), y - 7); ctx.lineTo(sx(v), y + 7); }
      ctx.stroke();
      d.U_px = sx(r.u[1]) - sx(r.u[0]);
    }
    if (r.rep && r.rep[0] !== null) {  // the repeatability: a thick bar (at least 2 px, so it shows)
      const a = sx(r.rep[0]), b = sx(r.rep[1]);
      ctx.globalAlpha = 0.6; ctx.fillRect(Math.min(a, (a + b) / 2 - 1), y - 4, Math.max(b - a, 2), 8);
      ctx.globalAlpha = 1;
      d.repeatability_px = b - a;
    }
    ctx.beginPath(); ctx.arc(sx(r.k), y, 3, 0, 2 * Math.PI); ctx.fill();
    drawn[r.name] = d;
  });
  canvas.dataset.drawn = 'intervals';
  canvas.dataset.intervals = JSON.stringify(drawn);
}

function drawPlot() {
  const canvas = document.getElementById('xy');
  const ctx = canvas.getContext('2d');
  const W = canvas.width, H = canvas.height, m = { l: 72, r: 20, t: 15, b: 48 };
  ctx.clearRect(0, 0, W, H);
  window.__textBoxes.xy = [];
  ctx.font = '12px sans-serif'; ctx.fillStyle = '#333';
  const xy = state.data.xy || { loading: [], unloading: [] };
  canvas.dataset.loadingPoints = xy.loading.length;  // drawn below: what a test waits for before a screenshot
  const lines = state.data.fit_lines || {};
  const pred = state.data.prediction || { line: [] };
  const all = [...xy.loading, ...xy.unloading];
  for (const b of ['loading', 'unloading']) if (lines[b]) all.push(...lines[b].line);
  if (!all.length) { canvasText(ctx, 'xy', 'waiting for fitted pairs…', W / 2, H / 2, 'center'); return; }
  let [x0, x1, y0, y1] = [Infinity, -Infinity, Infinity, -Infinity];
  for (const p of all) { x0 = Math.min(x0, p.x); x1 = Math.max(x1, p.x); y0 = Math.min(y0, p.y); y1 = Math.max(y1, p.y); }
  const padX = (x1 - x0) * 0.05 || 1e-6, padY = (y1 - y0) * 0.05 || 1e-3;
  x0 -= padX; x1 += padX; y0 -= padY; y1 += padY;
  const sx = (x) => m.l + (x - x0) / (x1 - x0) * (W - m.l - m.r);
  const sy = (y) => H - m.b - (y - y0) / (y1 - y0) * (H - m.t - m.b);
  ctx.strokeStyle = '#999'; ctx.lineWidth = 1;
  ctx.strokeRect(m.l, m.t, W - m.l - m.r, H - m.t - m.b);
  // tick labels: x centred under their tick, y right-aligned left of the frame; the axis titles outside them
  const moment = axisOf().axis.startsWith('m');
  for (let i = 0; i <= 5; i++) {
    const x = x0 + (x1 - x0) * i / 5, y = y0 + (y1 - y0) * i / 5;
    canvasText(ctx, 'xy', (x * 1e6).toFixed(1), sx(x), H - m.b + 16, 'center');
    canvasText(ctx, 'xy', y.toFixed(2), m.l - 6, sy(y) + 4, 'right');
  }
  canvasText(ctx, 'xy', moment ? 'rotation [µrad]' : 'displacement [µm]', (m.l + W - m.r) / 2, H - 8, 'center');
  const widest = Math.max(...window.__textBoxes.xy.filter((b) => b.left + b.width <= m.l).map((b) => b.width));
  canvasText(ctx, 'xy', moment ? 'moment [N·m]' : 'force [N]', Math.max(14, m.l - 6 - widest - 8),
    (m.t + H - m.b) / 2, 'center', true);
  const colors = { loading: '#1f77b4', unloading: '#e07b00' };
  for (const b of ['loading', 'unloading']) {
    ctx.fillStyle = colors[b];
    for (const p of xy[b]) ctx.fillRect(sx(p.x) - 1.5, sy(p.y) - 1.5, 3, 3);
    const l = lines[b];
    if (l && l.line.length) {
      ctx.globalAlpha = 0.2; ctx.beginPath();
      l.upper.forEach((p, i) => (i ? ctx.lineTo(sx(p.x), sy(p.y)) : ctx.moveTo(sx(p.x), sy(p.y))));
      [...l.lower].reverse().forEach((p) => ctx.lineTo(sx(p.x), sy(p.y)));
      ctx.closePath(); ctx.fill(); ctx.globalAlpha = 1;
      ctx.strokeStyle = colors[b]; ctx.lineWidth = 2; ctx.beginPath();
      l.line.forEach((p, i) => (i ? ctx.lineTo(sx(p.x), sy(p.y)) : ctx.moveTo(sx(p.x), sy(p.y))));
      ctx.stroke();
    }
  }
  const fan = lines.loading, eL = (state.data.estimate || {}).loading;
  if (fan && fan.line.length && eL && eL.U !== null && eL.stiffness !== null) {
    // k ± U of the loading branch: two dotted lines through its fit's centroid (the repeatability is the shaded band)
    const xc = fan.x_mean, yc = fan.stiffness * fan.x_mean + fan.intercept;
    const xs = [fan.line[0].x, fan.line[fan.line.length - 1].x];
    ctx.save();
    ctx.beginPath(); ctx.rect(m.l, m.t, W - m.l - m.r, H - m.t - m.b); ctx.clip();
    ctx.strokeStyle = colors.loading; ctx.setLineDash([2, 4]); ctx.lineWidth = 1.5;
    for (const k of [eL.stiffness - eL.U, eL.stiffness + eL.U]) {
      ctx.beginPath(); ctx.moveTo(sx(xs[0]), sy(yc + k * (xs[0] - xc))); ctx.lineTo(sx(xs[1]), sy(yc + k * (xs[1] - xc)));
      ctx.stroke();
    }
    ctx.restore();
  }
  if (pred.line.length) {
    ctx.save();
    ctx.beginPath(); ctx.rect(m.l, m.t, W - m.l - m.r, H - m.t - m.b); ctx.clip();  // a steep line stays in the frame
    ctx.strokeStyle = '#2a9d2a'; ctx.setLineDash([8, 5]); ctx.lineWidth = 2; ctx.beginPath();
    pred.line.forEach((p, i) => (i ? ctx.lineTo(sx(p.x), sy(p.y)) : ctx.moveTo(sx(p.x), sy(p.y))));
    ctx.stroke(); ctx.restore();
  }
}

function drawScene() {
  // An oblique view of the SceneUpdate (frame crane_view, z up): lines, the platform triangle, the force arrow.
  const scene = state.data.scene;
  const canvas = document.getElementById('scene');
  const ctx = canvas.getContext('2d');
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  canvas.dataset.drawn = scene && scene.entities.length ? 'crane' : '';  // what a test waits for (as above)
  window.__textBoxes.scene = [];
  if (!scene || !scene.entities.length) {
    ctx.font = '12px sans-serif'; ctx.fillStyle = '#333';
    canvasText(ctx, 'scene', 'waiting for the crane…', canvas.width / 2, canvas.height / 2, 'center');
    return;
  }
  const e = scene.entities[0];
  const yaw = 0.6, pitch = 0.35, s = 480;
  const project = (p) => {
    const x = p.x * Math.cos(yaw) - p.y * Math.sin(yaw), d = p.x * Math.sin(yaw) + p.y * Math.cos(yaw);
    // the crane left of centre: the column of wire labels is at the right
    return [canvas.width * 0.38 + s * x, canvas.height - 60 - s * (p.z * Math.cos(pitch) - d * Math.sin(pitch))];
  };
  const rgba = (c) => `rgba(${Math.round(c.r * 255)},${Math.round(c.g * 255)},${Math.round(c.b * 255)},${c.a})`;
  for (const t of e.triangles) {
    ctx.fillStyle = rgba(t.color); ctx.beginPath();
    t.points.forEach((p, i) => { const [u, v] = project(p); i ? ctx.lineTo(u, v) : ctx.moveTo(u, v); });
    ctx.closePath(); ctx.fill();
  }
  for (const l of e.lines) {
    ctx.strokeStyle = rgba(l.color); ctx.lineWidth = l.thickness; ctx.beginPath();
    if (l.type === 2) {
      for (let i = 0; i + 1 < l.points.length; i += 2) {
        const [a, b] = project(l.points[i]), [c, d] = project(l.points[i + 1]);
        ctx.moveTo(a, b); ctx.lineTo(c, d);
      }
    } else {
      l.points.forEach((p, i) => { const [u, v] = project(p); i ? ctx.lineTo(u, v) : ctx.moveTo(u, v); });
      if (l.type === 1) ctx.closePath();
    }
    ctx.stroke();
  }
  for (const a of e.arrows) {
    const q = a.pose.orientation, o = a.pose.position;
    // +x turned by the quaternion: the arrow's direction
    const dir = { x: 1 - 2 * (q.y * q.y + q.z * q.z), y: 2 * (q.x * q.y + q.z * q.w), z: 2 * (q.x * q.z - q.y * q.w) };
    const len = a.shaft_length + a.head_length;
    const [u0, v0] = project(o), [u1, v1] = project({ x: o.x + dir.x * len, y: o.y + dir.y * len, z: o.z + dir.z * len });
    ctx.strokeStyle = rgba(a.color); ctx.lineWidth = 3; ctx.beginPath(); ctx.moveTo(u0, v0); ctx.lineTo(u1, v1); ctx.stroke();
    const ang = Math.atan2(v1 - v0, u1 - u0);
    ctx.beginPath(); ctx.moveTo(u1, v1);
    ctx.lineTo(u1 - 10 * Math.cos(ang - 0.4), v1 - 10 * Math.sin(ang - 0.4));
    ctx.lineTo(u1 - 10 * Math.cos(ang + 0.4), v1 - 10 * Math.sin(ang + 0.4)); ctx.closePath();
    ctx.fillStyle = rgba(a.color); ctx.fill();
  }
  // The texts, placed so that none covers another: the wire labels in a column at the right, each with a swatch of
  // its wire's colour and a leader line to the wire's middle; the others near their anchor where they cover no
  // text and not the platform; the compliance ellipsoid's caption is the legend under the canvas.
  ctx.font = '11px sans-serif';
  const placed = [];
  const platform = e.triangles.length ? e.triangles[0].points.map(project) : [];
  const obstacle = platform.length ? {
    left: Math.min(...platform.map((p) => p[0])), top: Math.min(...platform.map((p) => p[1])),
    width: Math.max(...platform.map((p) => p[0])) - Math.min(...platform.map((p) => p[0])),
    height: Math.max(...platform.map((p) => p[1])) - Math.min(...platform.map((p) => p[1])) } : null;
  const W = canvas.width, H = canvas.height;
  const put = (t, x, y) => {
    ctx.fillStyle = rgba(t.color);
    canvasText(ctx, 'scene', t.text, x, y);
    placed.push(window.__textBoxes.scene[window.__textBoxes.scene.length - 1]);
  };
  const wireLines = e.lines.filter((l) => l.type === 2);  // the six wires, in order (the loops are LINE_LOOPs)
  let row = 0;
  for (const t of e.texts) {
    if (!WIRE_LABEL.test(t.text)) continue;
    const [u, v] = project(t.pose.position);
    const x = W - 112, y = 16 + 15 * row;
    const colour = wireLines[row] ? rgba(wireLines[row].color) : '#555';
    ctx.strokeStyle = colour; ctx.globalAlpha = 0.6; ctx.lineWidth = 1; ctx.setLineDash([2, 2]);
    ctx.beginPath(); ctx.moveTo(u, v); ctx.lineTo(x - 12, y - 4); ctx.stroke(); ctx.setLineDash([]);
    ctx.globalAlpha = 1; ctx.fillStyle = colour; ctx.fillRect(x - 11, y - 8, 8, 8);
    put(t, x, y);
    row++;
  }
  for (const t of e.texts) {
    if (WIRE_LABEL.test(t.text) || t.text.startsWith('compliance')) continue;
    const [u, v] = project(t.pose.position);
    const w = ctx.measureText(t.text).width;
    const candidates = [[u - w / 2, v], [u + 6, v], [u - w - 6, v], [u + 6, v + 16], [u - w - 6, v + 16],
      [u + 6, v - 16], [u - w - 6, v - 16], [u - w / 2, v + 22], [u - w / 2, v - 22]];
    for (let y = H - 6; y > 14; y -= 15) candidates.push([6, y]);  // else the lowest free line at the left
    const fits = ([x, y]) => {
      const box = { left: x, top: y - 11, width: w, height: 14 };
      return x >= 0 && x + w <= W && y - 11 >= 0 && y + 3 <= H && !placed.some((b) => overlaps(b, box, 2)) &&
        !(obstacle && overlaps(obstacle, box));
    };
    const [x, y] = candidates.find(fits) || [6, H - 6];
    put(t, x, y);
  }
  const scale = e.metadata.find((kv) => kv.key === 'deflection_scale');
  const ellipsoid = e.metadata.find((kv) => kv.key === 'compliance_force_n');
  canvas.dataset.ellipsoid = ellipsoid ? 'drawn' : '';
  if (scale) document.getElementById('scale').textContent = `deflection shown ×${Number(scale.value)}`;
  document.getElementById('ellipsoid-text').textContent = ellipsoid ?
    `(magenta): displacement under ${Number(ellipsoid.value)} N in any direction, ×${Number(scale.value)}` :
    'waiting for the 6×6 fit…';
}

function frame(now) {
  if (state.dirty.size && now - state.drawnAt >= DRAW_PERIOD_MS) {
    state.drawnAt = now;
    const parts = state.dirty;
    state.dirty = new Set();
    if (parts.has('text') || parts.has('plot')) updateText();  // the plot's caption is text too
    if (parts.has('wires')) updateWires();
    if (parts.has('plot')) drawPlot();
    if (parts.has('scene')) drawScene();
    if (parts.has('stiffness6')) updateStiffness6();
  }
  requestAnimationFrame(frame);
}

setInterval(() => {
  document.getElementById('rate').textContent = `${state.messages - state.lastCount} messages/s`;
  document.getElementById('rate').dataset.rate = state.messages - state.lastCount;
  state.lastCount = state.messages;
}, 1000);

buildTables();
fetch('config.json').then((r) => r.json()).then((config) => { setRun(config.run || 'one_axis'); connect(config); });
requestAnimationFrame(frame);
