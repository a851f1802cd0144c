// The live view's 6×6 panel (loaded before app.js, whose helpers it uses when called: state, compact, diverging,
// canvasText): the measured K against the model's tangent, K2 and the status, the chosen row of K with its
// repeatability and its U, both intervals of each of the row's entries drawn, and what U counts.
'use strict';

function updateStiffness6() {
  // The 6×6 panel (its tables made at the start, their cells rewritten) and the chosen row of K.
  const k6 = state.data.stiffness6;
  if (!k6) return;
  const table = document.getElementById('stiffness6');
  k6.rows.forEach((row, i) => row.cells.forEach((c, j) => {
    const td = table.rows[i + 1].cells[j + 1];
    td.textContent = compact(c.measured);
    td.dataset.value = c.measured === null ? '' : String(c.measured);
    td.dataset.relative = c.relative_error === null ? '' : String(c.relative_error);
    td.title = `${row.load}/${c.displacement}: ${c.measured === null ? '–' : c.measured} ` +
      `[${c.ci95_low === null ? '–' : c.ci95_low}, ${c.ci95_high === null ? '–' : c.ci95_high}] (repeatability)` +
      (c.U === null || c.U === undefined ? '' : `, ± ${c.U} (U, 95 %)`) + `, tangent ${c.tangent}`;
    const cls = c.model_zero ? 'k6 model-zero' : 'k6';
    if (td.className !== cls) td.className = cls;
    td.style.background = c.model_zero || c.relative_error === null ? '' : diverging(c.relative_error);
  }));
  const badge = document.getElementById('stiffness6-level');
  badge.className = `level-${k6.level}`;
  badge.textContent = k6.level_name;
  badge.dataset.level = k6.level;
  const k2 = k6.k2;
  const k2U = k2.U === null || k2.U === undefined ? '' : `, ± ${compact(k2.U)} (U, 95 %)`;
  document.getElementById('stiffness6-k2').textContent = k6.fit ? `K2 = ${compact(k2.measured)} ` +
    `[${compact(k2.ci95_low)}, ${compact(k2.ci95_high)}] N/rad (repeatability)${k2U}, model tangent ` +
    `${compact(k2.tangent)}` : `K2: waiting for the 6×6 fit… (model tangent ${compact(k2.tangent)} N/rad)`;
  document.getElementById('stiffness6-message').textContent = k6.message || 'waiting for the six-axis estimator…';
  const row = k6.rows[state.k6Row], rowTable = document.getElementById('k6-row-table');
  row.cells.forEach((c, j) => {
    const cells = rowTable.rows[j + 1].cells;
    cells[1].textContent = compact(c.measured);
    cells[2].textContent = c.ci95_low === null ? '–' : `${compact(c.ci95_low)} .. ${compact(c.ci95_high)}`;
    // U when the six-axis estimator states it (the field on the channel); until then said so, never a blank
    const hasU = c.U !== null && c.U !== undefined;
    cells[3].textContent = hasU ? `± ${compact(c.U)}` : (c.measured === null ? '–' : 'not stated');
    cells[3].dataset.value = hasU ? `${c.U_low},${c.U_high}` : '';
    cells[4].textContent = compact(c.tangent);
    cells[5].textContent = c.model_zero ? 'model: 0' :
      (c.relative_error === null ? '–' : `${(100 * c.relative_error).toFixed(2)} %`);
  });
  // what U counts (the estimator's statement: "statistical only" named for what no sensor declares)
  document.getElementById('stiffness6-uncertainty').textContent = !k6.fit ? 'U: waiting for the 6×6 fit…' :
    (k6.uncertainty ? `U (GUM, 95 %): ${k6.uncertainty}` : 'U: not stated by the six-axis estimator for this fit');
  drawK6Intervals(row);
}

// The chosen row's six entries, each on a line of its own scale (their units differ): a dot at K, a thick bar over
// its repeatability (the fit's 95 %), a thin line with end ticks over K ± U, a green tick at the model's tangent.
// The canvas says what it drew (in pixels) for tests.
function drawK6Intervals(row) {
  const canvas = document.getElementById('k6int');
  const ctx = canvas.getContext('2d');
  const W = canvas.width, H = canvas.height, m = { l: 44, r: 8, t: 4, b: 4 }, lw = 86;
  ctx.clearRect(0, 0, W, H);
  window.__textBoxes.k6int = [];
  ctx.font = '11px sans-serif';
  const rowH = (H - m.t - m.b) / 6, drawn = {};
  row.cells.forEach((c, j) => {
    const y = m.t + rowH * (j + 0.5);
    ctx.fillStyle = '#333';
    canvasText(ctx, 'k6int', c.displacement, 4, y + 4);
    if (c.measured === null) return;
    const values = [c.measured, c.tangent, c.ci95_low, c.ci95_high, c.U_low, c.U_high].filter((v) => v !== null);
    let lo = Math.min(...values), hi = Math.max(...values);
    const pad = (hi - lo) * 0.08 || Math.abs(hi) * 1e-3 || 1;
    lo -= pad; hi += pad;
    const x0 = m.l + lw, x1 = W - m.r - lw;
    const sx = (v) => x0 + (v - lo) / (hi - lo) * (x1 - x0);
    canvasText(ctx, 'k6int', compact(lo), x0 - 4, y + 4, 'right');
    canvasText(ctx, 'k6int', compact(hi), x1 + 4, y + 4, 'left');
    ctx.strokeStyle = '#ddd'; ctx.lineWidth = 1;
    ctx.beginPath(); ctx.moveTo(x0, y); ctx.lineTo(x1, y); ctx.stroke();
    const d = { k: c.measured };
    ctx.strokeStyle = '#2a9d2a'; ctx.lineWidth = 2;  // the model's tangent
    ctx.beginPath(); ctx.moveTo(sx(c.tangent), y - 6); ctx.lineTo(sx(c.tangent), y + 6); ctx.stroke();
    ctx.strokeStyle = '#333'; ctx.fillStyle = '#333';
    if (c.U !== null && c.U !== undefined) {  // K ± U: a thin line with end ticks
      ctx.lineWidth = 1.5; ctx.beginPath();
      ctx.moveTo(sx(c.U_low), y); ctx.lineTo(sx(c.U_high), y);
      for (const v of [c.U_low, c.U_high]) { ctx.moveTo(sx(v), y - 5); ctx.lineTo(sx(v), y + 5); }
      ctx.stroke();
      d.U_px = sx(c.U_high) - sx(c.U_low);
    }
    if (c.ci95_low !== null) {  // the repeatability: a thick bar (at least 2 px, so it shows)
      const a = sx(c.ci95_low), b = sx(c.ci95_high);
      ctx.fillStyle = '#1f77b4'; ctx.globalAlpha = 0.6;
      ctx.fillRect(Math.min(a, (a + b) / 2 - 1), y - 3, Math.max(b - a, 2), 6);
      ctx.globalAlpha = 1;
      d.repeatability_px = b - a;
    }
    ctx.fillStyle = '#000';
    ctx.beginPath(); ctx.arc(sx(c.measured), y, 2.5, 0, 2 * Math.PI); ctx.fill();
    drawn[c.displacement] = d;
  });
  canvas.dataset.drawn = Object.keys(drawn).length ? 'intervals' : '';
  canvas.dataset.intervals = JSON.stringify(drawn);
}
