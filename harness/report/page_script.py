"""The script of report.html (harness/report/html.py): plain JavaScript over the page's
data table, drawing with Plotly.  Kept as a Python string so that it ships with the
package wherever it is installed."""

PAGE_SCRIPT = r"""
(function () {
'use strict';
const D = JSON.parse(document.getElementById('report-data').textContent);
// Each solver's own colour, family, marker (Plotly symbol) and line dash (Plotly dash), as the PNGs
// draw it (style.py SolverStyles).
const COLOR = {}, FAMILY = {}, SYMBOL = {}, DASH = {};
D.families.forEach(f => f.solvers.forEach(s => { COLOR[s.name] = s.color; FAMILY[s.name] = f.name;
  SYMBOL[s.name] = s.symbol; DASH[s.name] = s.dash; }));
// A solver's line in its own dash and marker (the marker's sizes set by sparseMarks).
const ownLine = (so, col, extra) => ({line: Object.assign({color: col, dash: DASH[so] || 'solid'}, extra || {}),
  marker: {symbol: SYMBOL[so] || 'circle', color: col}});
const MARK_SIZE = 6;
// A line of many points wears its marker at points D.markEvery of the way apart along it, as the PNG's
// matplotlib markevery (panels.py MARK_EVERY): the way measured on the chart's axes (log where an axis
// is; the plot taken as a unit square, whose diagonal is the whole way), so that two solvers of one
// shade differ in shape and the lines stay readable.  The other points get size 0.
function sparseMarks(traces, xLog, yLog) {
  const on = log => v => v === null || v === undefined || !(log ? v > 0 : Number.isFinite(v)) ? null :
    (log ? Math.log10(v) : v);
  const X = traces.map(t => t.x.map(on(xLog))), Y = traces.map(t => t.y.map(on(yLog)));
  const span = vs => { const v = [].concat(...vs).filter(x => x !== null);
    return v.length ? (v.reduce((a, b) => Math.max(a, b)) - v.reduce((a, b) => Math.min(a, b))) || 1 : 1; };
  const sx = span(X), sy = span(Y), every = D.markEvery * Math.SQRT2;
  traces.forEach((t, k) => {
    let way = 0, last = null;
    t.marker.size = X[k].map((x, i) => {
      const y = Y[k][i];
      if (x === null || y === null) return 0;
      if (last) way += Math.hypot((x - last[0]) / sx, (y - last[1]) / sy);
      const mark = !last || way >= every;
      if (mark) way = 0;
      last = [x, y];
      return mark ? MARK_SIZE : 0;
    });
  });
}
const state = {solvers: new Set(Object.keys(COLOR)), scenes: new Set(D.scenes), profiles: new Set(D.profiles)};
// A scene whose row chart gives colours ((solver, colour) pairs in drawing order: Fig. 6's K from
// dark to light (viridis), as its PNG) draws those solvers in them, first and in that order, in every one
// of its charts; other solvers take their family colours and follow by name.
const OWN = {};
D.rowcharts.filter(c => c.colors && c.colors.length).forEach(c => {
  OWN[c.scene] = new Map(c.colors.map(([s, col], i) => [s, [i, col]])); });
const colorIn = (scene, so) => OWN[scene] && OWN[scene].has(so) ? OWN[scene].get(so)[1] : COLOR[so];
const rankIn = (scene, so) => OWN[scene] && OWN[scene].has(so) ? OWN[scene].get(so)[0] : Infinity;
function bySceneOrder(scene, solverOf) {
  return (a, b) => { const ra = rankIn(scene, solverOf(a)), rb = rankIn(scene, solverOf(b));
    return ra !== rb ? (ra < rb ? -1 : 1) : (a < b ? -1 : a > b ? 1 : 0); };
}
const charts = [];   // {div, scene, draw: () => [traces, layout]}
// A work-precision point's size by its profile (larger: tighter), as the static figure's
// (D.profileSizes: sections/generic.py page_marker_sizes; key '': a profile it does not list); its
// shape is its solver's own symbol, so that two solvers of one family differ in shape as well as in colour.
const profileSize = pr => D.profileSizes[pr] || D.profileSizes[''];
const fmt = v => (v === null || v === undefined) ? '-' : Number.isInteger(v) && Math.abs(v) < 1e6 ? String(v) : (Math.abs(v) >= 1e-3 && Math.abs(v) < 1e5 ?
  Number(v.toPrecision(3)).toString() : v.toExponential(1));
const HOVER = 'instance %{customdata[0]}, step %{customdata[1]}, n %{customdata[2]}<br>' +
  'solver %{customdata[9]} (%{customdata[10]})<br>kkt_error %{customdata[3]}, p error %{customdata[4]}, ' +
  'load error %{customdata[5]}<br>time %{customdata[6]} s%{customdata[11]}, iterations %{customdata[7]}, status %{customdata[8]}' +
  '<extra></extra>';
// A row whose answer served as its step's reference (r.ref) has p error 0 by construction: the hover
// says 'ref', and the p-error chart leaves it out (at the log floor it would read as exact).
const custom = r => [r.inst, r.st, r.n, fmt(r.kkt), r.ref ? 'ref' : fmt(r.perr), fmt(r.lerr), fmt(r.t), r.it, r.stt, r.so, r.pr,
  r.reps > 1 ? ' (the least of ' + r.reps + ' repeats)' : ''];
const measured = (r, key) => r[key] !== null && !(key === 'perr' && r.ref);
const base = lab => lab.replace(/ \(warm\)$/, '');

function rowsOf(scene) {
  return D.rows.filter(r => r.sc === scene && state.solvers.has(r.so) && state.profiles.has(r.pr));
}
function groupBy(rows, key) {
  const m = new Map();
  rows.forEach(r => { const k = key(r); if (!m.has(k)) m.set(k, []); m.get(k).push(r); });
  return m;
}
function axisType(vals) {
  const v = vals.filter(x => x !== null && x > 0);
  if (!v.length) return 'linear';
  return Math.max(...v) / Math.min(...v) > 10 ? 'log' : 'linear';
}
function layout(title, xt, yt, xs, ys, extra) {
  return Object.assign({title: {text: title, font: {size: 13}}, margin: {l: 60, r: 10, t: 40, b: 50},
    xaxis: {title: {text: xt}, type: axisType(xs), exponentformat: 'power'},
    yaxis: {title: {text: yt}, type: axisType(ys), exponentformat: 'power'},
    legend: {font: {size: 10}}, hovermode: 'closest'}, extra || {});
}
// A chart of more than D.maxSeries series draws fewer, narrowing step by step while it still has
// too many: the scene's first D.maxSeries solvers in D.lead's order (the best of each family, then
// the others by solved share, then SGM), then only the lead profile, then the first instances (a
// chart of one curve per instance), then the first D.maxSeries; the other series are hidden and
// left out of the legend (a legend of 70 entries, 60 of them greyed, could not be read; nor could
// 70 series drawn at once tell their solvers apart), and the legend's title says how many are drawn,
// why those, and that ticking fewer solvers or profiles in the picker draws the others.  Each trace
// carries meta.so (its solver; none: no solver narrowing), meta.pr (its profile) and meta.inst
// (its instance) where it has them.
const BEST_FIRST = 'the best of each family first';
function thin(scene, traces, lay) {
  if (traces.length <= D.maxSeries) return [traces, lay];
  const lead = D.lead[scene];
  const why = [];
  let keep = t => true;
  const narrow = (test, word) => {
    const k0 = keep, k1 = t => k0(t) && test(t);
    if (traces.filter(k0).length > D.maxSeries && traces.some(k1)) { keep = k1; why.push(word); }
  };
  if (lead) {
    const present = new Set(traces.map(t => t.meta.so).filter(s => s !== undefined));
    if (present.size > D.maxSeries) {
      const first = new Set(lead.order.filter(s => present.has(s)).slice(0, D.maxSeries));
      narrow(t => first.has(t.meta.so), BEST_FIRST);
    }
    narrow(t => t.meta.pr === undefined || t.meta.pr === lead.profile, 'at ' + lead.profile);
  }
  const kept = traces.filter(keep);
  if (kept.length > D.maxSeries && kept.every(t => t.meta.inst !== undefined)) {
    const insts = [...new Set(kept.map(t => t.meta.inst))];
    const most = Math.max(...insts.map(i => kept.filter(t => t.meta.inst === i).length));
    const first = new Set(insts.slice(0, Math.max(1, Math.floor(D.maxSeries / most))));
    narrow(t => first.has(t.meta.inst), 'the first ' + first.size + ' of ' + insts.length + ' instances');
  }
  const shown = new Set(traces.filter(keep).slice(0, D.maxSeries));
  narrow(t => shown.has(t), 'the first ' + D.maxSeries);
  if (traces.every(keep)) return [traces, lay];
  traces.forEach(t => { if (!keep(t)) { t.visible = false; t.showlegend = false; } });
  // counted in solvers where the narrowing is by solver alone (a solver's profiles and instances are one)
  const bySolver = why.length === 1 && why[0] === BEST_FIRST;
  const count = ts => bySolver ? new Set(ts.map(t => t.meta.so)).size : ts.length;
  const shownNow = traces.filter(keep);
  lay.legend.title = {text: count(shownNow) + ' of ' + count(traces) + (bySolver ? ' solvers' : ' series') + ' drawn (' +
    why.join(', ') + ');<br>tick fewer ' + (bySolver ? 'solvers or profiles' : 'profiles') + ' on the left for the others',
    font: {size: 10}};
  return [traces, lay];
}
// A row not solved is marked by its status (r.uk: a key of D.unsolved, the static figures'
// UNSOLVED_MARKS), with one legend entry per kind drawn, a solved one by its solver's own symbol
// (html.py SOLVER_SYMBOLS); against the load (x 'dl') a row sits at its
// step's load (the median of the step's solved answers), and a row whose step nobody solved is
// left out, as in the static figures: the chart says how many, and says why when it draws nothing.
function unsolvedMark(r, col) {
  const m = r.uk === null ? null : D.unsolved[r.uk];
  return m ? {symbol: m.symbol, color: m.color, size: 10} : {symbol: SYMBOL[r.so] || 'circle', color: col, size: 6};
}
function unsolvedLegend(rows) {
  const kinds = new Set(rows.map(r => r.uk).filter(k => k !== null));
  return Object.keys(D.unsolved).filter(k => kinds.has(k)).map(k => ({type: 'scatter', mode: 'markers',
    name: D.unsolved[k].label, meta: {}, x: [null], y: [null], hoverinfo: 'skip',
    marker: {symbol: D.unsolved[k].symbol, color: D.unsolved[k].color, size: 10, line: {width: 2}}}));
}
// A series with an unsolved mark would show the mark of its first point as its legend icon (Plotly
// draws a trace's legend icon from its first point's marker, and its size from their mean; a series
// of sparse marks, sparseMarks, would show a speck): the series stays out of the legend, and a
// stand-in of no point, in its legend group (a click on it shows or hides the series), shows the
// series' own line and marker there.
function ownLegend(t) {
  t.showlegend = false;
  t.legendgroup = t.name;
  return {type: 'scatter', mode: t.mode, name: t.name, meta: t.meta, legendgroup: t.name, visible: t.visible,
    x: [null], y: [null], hoverinfo: 'skip', line: t.line, marker: {color: t.line.color, symbol: SYMBOL[t.meta.so] || 'circle', size: MARK_SIZE}};
}
// A chart with nothing to draw says why on its (empty) plot, in lines of at most NOTE_CHARS
// characters (an annotation does not wrap): the words of report.md's "No figure." (panels.py).
const NOTE_CHARS = 70;
function wrapNote(text) {
  if (text.includes('<br>')) return text;
  const lines = [''];
  text.split(' ').forEach(w => { const i = lines.length - 1;
    if (lines[i] && lines[i].length + w.length + 1 > NOTE_CHARS) lines.push(w); else lines[i] += (lines[i] ? ' ' : '') + w; });
  return lines.join('<br>');
}
function emptyNote(lay, text) {
  lay.annotations = (lay.annotations || []).concat([{text: wrapNote(text), showarrow: false, xref: 'paper', yref: 'paper',
    x: 0.5, y: 0.5, font: {color: 'gray'}}]);
  [lay.xaxis, lay.yaxis].forEach(a => Object.assign(a, {showticklabels: false, zeroline: false}));
}
// One point per cell (solver label, profile, instance, step), as the PNGs' (core.py per_cell): the
// repeats of a cell are folded into the least time, and the cell is solved only when every repeat is
// (else it wears the mark of its first repeat not solved); the hover says how many repeats.
function foldRepeats(rows) {
  const g = groupBy(rows, r => [r.lab, r.pr, r.inst, r.st].join('\u0001'));
  return [...g.values()].map(rs => {
    const fast = rs.reduce((a, b) => (b.t < a.t ? b : a));
    const bad = rs.find(r => r.stt !== 'solved');
    return Object.assign({}, fast, bad ? {stt: bad.stt, uk: bad.uk} : {}, {reps: rs.length});
  });
}
function lineChart(scene, c) {
  return () => {
    const xKey = c.x;
    // only the profile and instance its section's PNG draws, where it names them
    const picked = foldRepeats(rowsOf(scene).filter(r => r.t !== null && (!c.profile || r.pr === c.profile) &&
      (!c.instance || r.inst === c.instance)));
    const rows = picked.filter(r => r[xKey] !== null);
    const multiProf = new Set(rows.map(r => r.pr)).size > 1;
    const g = groupBy(rows, r => r.lab + (multiProf ? ' [' + r.pr + ']' : '') + (c.by_instance ? ' ' + r.inst : ''));
    const traces = [];
    [...g.keys()].sort(bySceneOrder(scene, k => g.get(k)[0].so)).forEach(k => {
      const rs = g.get(k).slice().sort((a, b) => a[xKey] - b[xKey]);
      const so = rs[0].so, col = colorIn(scene, so), marks = rs.map(r => unsolvedMark(r, col));
      // against the load a line joins the steps of one load history: the points of several
      // instances stay unjoined (against n, the instances are the sizes the line runs through)
      const mode = xKey === 'dl' && new Set(rs.map(r => r.inst)).size > 1 ? 'markers' : 'lines+markers';
      traces.push({type: 'scatter', mode: mode, name: k, meta: {so: so, pr: rs[0].pr, inst: c.by_instance ? rs[0].inst : undefined, marked: rs.some(r => r.uk !== null)},
        x: rs.map(r => r[xKey]), y: rs.map(r => r.t),
        customdata: rs.map(custom), hovertemplate: HOVER, line: {color: col, dash: rs[0].lab !== so ? 'dash' : 'solid'},
        marker: {color: marks.map(m => m.color), size: marks.map(m => m.size), symbol: marks.map(m => m.symbol),
          line: {width: marks.map(m => m.size > 6 ? 2 : 0), color: marks.map(m => m.color)}}});
    });
    const off = picked.length - rows.length;
    const unplaced = xKey === 'dl' && off > 0 && rows.length > 0;
    const lines = [[c.instance ? 'instance ' + c.instance : '', c.profile ? 'profile ' + c.profile + ', as report.md' : '']
      .filter(w => w).join(', '), unplaced ? off + ' solves not drawn: no answer at their step was solved' : '']
      .filter(w => w);
    const title = c.title + lines.map(w => '<br><span style="font-size:10px">' + esc(w) + '</span>').join('');
    const lay = layout(title, c.x_title, 'solve time [s]', rows.map(r => r[xKey]), rows.map(r => r.t));
    lay.margin.t += 20 * lines.length;
    const unpicked = c.profile && !state.profiles.has(c.profile);
    if (!rows.length) emptyNote(lay, unpicked ? 'this chart draws profile ' + esc(c.profile) + ' (report.md\'s): ' +
      'tick it among the profiles' : !picked.length ? 'no solve of the picked solvers and profiles to draw' :
      xKey === 'dl' ? 'nothing to draw: the load axis takes a step\'s load from its solved answers,<br>and none of ' +
        'the ' + picked.length + ' solves here was solved' : 'no solve here has a value on the x axis');
    const [drawn, lay2] = thin(scene, traces, lay);
    const standIns = drawn.filter(t => t.meta.marked).map(ownLegend);
    return [drawn.concat(standIns, unsolvedLegend(rows)), lay2];
  };
}
function wpChart(scene, key, yTitle) {
  return () => {
    const rows = rowsOf(scene).filter(r => r.t !== null && measured(r, key));
    const multi = new Set(rows.map(r => r.pr)).size > 1;  // as the PNG: sizes by profile where the scene ran several
    const g = groupBy(rows, r => r.so + '|' + r.pr);
    const traces = [];
    [...g.keys()].sort(bySceneOrder(scene, k => g.get(k)[0].so)).forEach(k => {
      const rs = g.get(k), so = rs[0].so, pr = rs[0].pr, col = colorIn(scene, so);
      traces.push({type: 'scatter', mode: 'markers', name: so, meta: {so: so, pr: pr}, legendgroup: so,
        x: rs.map(r => r.t), y: rs.map(r => Math.max(r[key], 1e-16)), customdata: rs.map(custom), hovertemplate: HOVER,
        marker: {color: rs.map(r => r.stt === 'solved' ? col : 'white'), line: {color: col, width: 1},
          symbol: SYMBOL[so] || 'circle', size: multi ? profileSize(pr) : profileSize('default')}});
    });
    const refs = key === 'perr' && rowsOf(scene).some(r => r.ref) ? '; reference\'s own not drawn' : '';
    const lay = layout('run time against ' + yTitle + ' (' + scene + refs + ')', 'solve time [s]', yTitle,
      rows.map(r => r.t), [1, 10, 100]);
    lay.yaxis.type = 'log';
    const [drawn, lay2] = thin(scene, traces, lay);
    // one legend entry per solver (its profiles are one legend group, told apart by the marker's size,
    // which entries of their own explain), so that the legend holds the drawn solvers and no more
    const seen = new Set();
    drawn.forEach(t => { if (t.visible !== false) { t.showlegend = !seen.has(t.meta.so); seen.add(t.meta.so); } });
    const profs = multi ? [...new Set(drawn.filter(t => t.visible !== false).map(t => t.meta.pr))] : [];
    const sizes = profs.sort((a, b) => profileSize(a) - profileSize(b)).map(pr => ({type: 'scatter', mode: 'markers',
      name: 'profile ' + pr + ' (marker size)', meta: {}, x: [null], y: [null], hoverinfo: 'skip',
      marker: {symbol: 'circle', color: 'gray', size: profileSize(pr)}}));
    return [drawn.concat(sizes), lay2];
  };
}
// One chart per profile of the scene (p.profile null where it ran one: the title as before): a profile
// is its own accuracy target, and solvers are compared within one (html.py profiles_and_sgm).
function ppChart(scene, p) {
  return () => {
    const traces = Object.keys(p.curves).filter(s => state.solvers.has(s)).sort(bySceneOrder(scene, s => s)).map(s => Object.assign({
      // a curve at 0 all along (note null) or under an equal one (note: its solver), as report.md's legend says
      type: 'scatter', mode: 'lines+markers', name: s + (p.notes && s in p.notes ? ' (' + (p.notes[s] === null ?
        D.atZero : '= ' + p.notes[s]) + ')' : ''),
      meta: {so: s}, x: p.taus, y: p.curves[s],
      hovertemplate: s + ': %{y:.2f} within tau = %{x:.3g}<extra></extra>'}, ownLine(s, colorIn(scene, s), {shape: 'hv'})));
    const lay = layout('performance profile (' + scene + (p.profile ? ', profile ' + p.profile : '') + ', ' + p.n +
      ' problems)', 'tau (times the best time)', 'share of the ' + p.n + ' problems solved', p.taus, [0, 1]);
    lay.xaxis.type = 'log';
    lay.yaxis.range = [-0.02, 1.02];
    if (p.empty) emptyNote(lay, p.empty);
    sparseMarks(traces, true, false);
    const [drawn, lay2] = thin(scene, traces, lay);
    return [drawn.concat(drawn.map(ownLegend)), lay2];
  };
}
function counterexampleChart(scene, c) {
  return () => {
    const rows = rowsOf(scene);
    const g = groupBy(rows, r => r.so);
    const ns = [...new Set(rows.map(r => r.n))].sort((a, b) => a - b);
    const cats = ns.map(n => 'n = ' + n);
    const traces = [...g.keys()].sort().map(so => {
      const rs = g.get(so);
      const y = ns.map(n => { const x = rs.filter(r => r.n === n); if (!x.length) return null;
        return 100 * x.filter(r => r.stt !== 'solved').length / x.length; });  // the judge's verdict, as the section
      return {type: 'bar', name: so, meta: {so: so}, x: cats, y: y, marker: {color: colorIn(scene, so)},
        hovertemplate: so + ': %{y:.0f} % of seeds violate the LCP (judge: not solved) at %{x}<extra></extra>'};
    });
    if (c.reference && cats.length) traces.push({type: 'scatter', mode: 'lines', name: c.reference[1], x: cats,
      y: cats.map(() => c.reference[0]), line: {color: 'gray', dash: 'dash'}, hoverinfo: 'skip'});
    const lay = layout(c.title, c.x_title, 'seeds violating the LCP [%]', [], []);
    lay.xaxis.type = 'category';  // one group of bars per n: a linear axis would drop them all
    lay.yaxis.range = [0, 105];
    const bars = traces.filter(t => t.type === 'bar');
    return [thin(scene, bars, lay)[0].concat(traces.filter(t => t.type !== 'bar')), lay];
  };
}
// Each solver's representative trace: its own residual against time, or against iteration as
// D.traces.it_axis says (panels.iteration_axis: iteration + 1 on a log axis, so that iteration 0 is
// drawn; d.x holds the placed values); a trace equal to another's against iteration, drawn under it
// there, says so in its name on that chart.
function traceChart(useTime) {
  return () => {
    const T = D.traces, A = T.it_axis || {log: false, shift: 0, title: 'iteration'};
    const traces = Object.keys(T.solvers).filter(s => state.solvers.has(s)).map(s => {
      const d = T.solvers[s];
      return Object.assign({type: 'scatter', mode: 'lines+markers', name: s + (!useTime && d.same ? ' (same as ' + d.same + ')' : ''),
        meta: {so: s}, x: useTime ? d.t : d.x, y: d.r, customdata: d.it,
        hovertemplate: s + ' (' + FAMILY[s] + ', ' + d.where + '): residual %{y:.2e} at ' +
          (useTime ? '%{x:.3g} s' : 'iteration %{customdata}') + '<extra></extra>'}, ownLine(s, colorIn(T.scene, s)));
    });
    const xs = [].concat(...traces.map(t => t.x));
    const lay = layout('convergence traces (' + T.scene + '): own residual against ' + (useTime ? 'time' : 'iteration'),
      useTime ? 'elapsed [s]' : A.title, 'own residual', xs, [1, 100]);
    lay.yaxis.type = 'log';
    lay.xaxis.type = useTime || A.log ? 'log' : 'linear';
    if (T.empty) emptyNote(lay, T.empty);
    sparseMarks(traces, lay.xaxis.type === 'log', true);
    const [drawn, lay2] = thin(T.scene, traces, lay);
    return [drawn.concat(drawn.map(ownLegend)), lay2];
  };
}
// report.md's load-area figure (html.py load_area_data): A/A0 against the load over each surface's
// h'_rms, per instance of the picked scenes, and the lines of Persson and Bush-Gibson-Thomas.
function loadAreaChart() {
  return () => {
    const L = D.loadarea;
    const traces = L.series.filter(s => state.scenes.has(s.scene)).map(s => ({type: 'scatter',
      mode: 'lines+markers', name: s.name, meta: {}, x: s.x, y: s.y, customdata: s.step,
      hovertemplate: 'step %{customdata}: P/(E* A0 h\'_rms) = %{x:.3g}, A/A0 = %{y:.3g}<extra></extra>'}));
    const lines = L.lines.map(l => ({type: 'scatter', mode: 'lines', name: l.name, meta: {}, x: l.x, y: l.y,
      line: {color: 'black', dash: l.dash, width: 1}, hoverinfo: 'skip'}));
    const lay = layout(L.title, L.x_title, L.y_title, [1, 100], [1, 100]);
    lay.xaxis.type = 'log'; lay.yaxis.type = 'log';
    const [drawn, lay2] = thin('', traces, lay);
    return [drawn.concat(lines), lay2];
  };
}
// Text of the table (a solver, scene or figure name) as HTML text: never markup.
const esc = v => String(v).replace(/[&<>"']/g, c => ({'&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;', "'": '&#39;'})[c]);
function sgmTable(T, holder) {
  let sortCol = T.sort, asc = true;
  const pct = new Set(T.percent);
  function render() {
    const rows = T.rows.filter(r => state.solvers.has(r[0])).slice().sort((a, b) => {
      const x = a[sortCol], y = b[sortCol];
      if (x === y) return 0; if (x === null) return 1; if (y === null) return -1;
      return (x < y ? -1 : 1) * (asc ? 1 : -1); });
    const head = '<tr>' + T.columns.map((c, i) => '<th data-i="' + i + '">' + esc(c) + (i === sortCol ? (asc ? ' &#9650;' : ' &#9660;') : '') + '</th>').join('') + '</tr>';
    const body = rows.map(r => '<tr>' + r.map((v, i) => '<td>' + (pct.has(i) && v !== null ? Math.round(100 * v) + ' %' :
      (typeof v === 'number' ? fmt(v) : (v === null ? '-' : esc(v)))) + '</td>').join('') + '</tr>').join('');
    holder.innerHTML = '<table class="sgm">' + head + body + '</table>';
    holder.querySelectorAll('th').forEach(th => th.addEventListener('click', () => {
      const i = +th.dataset.i; if (i === sortCol) asc = !asc; else { sortCol = i; asc = true; } render(); }));
  }
  holder.render = render;
  render();
}
function addChart(parent, scene, draw) {
  const div = document.createElement('div');
  div.className = 'chart';
  parent.appendChild(div);
  charts.push({div: div, scene: scene, draw: draw});
}
function build() {
  const main = document.getElementById('charts');
  D.scenes.forEach(scene => {
    const sec = document.createElement('section');
    sec.className = 'scene'; sec.dataset.scene = scene;
    sec.innerHTML = '<h2>' + esc(scene) + '</h2>';
    const grid = document.createElement('div'); grid.className = 'grid'; sec.appendChild(grid);
    const has = D.rows.some(r => r.sc === scene);
    D.rowcharts.filter(c => c.scene === scene).forEach(c => addChart(grid, scene, c.drawer === 'unsolved-share'
      ? counterexampleChart(scene, c) : lineChart(scene, c)));
    D.charts.filter(c => c.scene === scene).forEach(c => addChart(grid, scene, () => [c.data, c.layout]));
    if (has) {
      addChart(grid, scene, wpChart(scene, 'kkt', 'kkt_error'));
      if (D.rows.some(r => r.sc === scene && measured(r, 'perr'))) addChart(grid, scene, wpChart(scene, 'perr', 'p error'));
    }
    (D.pp[scene] || []).forEach(p => addChart(grid, scene, ppChart(scene, p)));
    (D.sgm[scene] || []).forEach(T => {
      const h = document.createElement('div');
      // the SGM's words are report.md's (sections/generic.py SGM_CAPTION), without its Markdown
      h.innerHTML = '<h3>problems solved and shifted geometric mean of solve time' +
        (T.profile ? ', profile ' + esc(T.profile) + ' (' + T.problems + ' problems)' : '') + ' (click a header to sort)</h3>' +
        '<p class="note">solved / problems: of every problem of the scene' + (T.profile ? ' at this profile' : '') +
        ', a skipped or not run cell counting as not solved; solved / attempted: of the cells the solver ran. ' +
        esc(T.note.replace(/\*\*/g, '')) + '</p>';
      const t = document.createElement('div'); t.className = 'tablebox';
      h.appendChild(t); sec.appendChild(h); sgmTable(T, t);
      charts.push({div: null, scene: scene, table: t});
    });
    main.appendChild(sec);
  });
  const field = document.createElement('section');
  field.className = 'scene'; field.dataset.scene = '';
  field.innerHTML = '<h2>The contact fields and convergence</h2>';
  const grid = document.createElement('div'); grid.className = 'grid'; field.appendChild(grid);
  D.charts.filter(c => !c.scene).forEach(c => addChart(grid, '', () => [c.data, c.layout]));
  if (D.loadarea.series) addChart(grid, '', loadAreaChart());
  if (D.traces.scene) { addChart(grid, '', traceChart(false)); addChart(grid, '', traceChart(true)); }
  D.images.forEach(im => { const f = document.createElement('figure');
    f.innerHTML = '<img class="static" alt="' + esc(im.name) + '" src="' + esc(im.src) + '"><figcaption>' + esc(im.name) + ' (static, as in report.md)</figcaption>';
    field.appendChild(f); });
  main.appendChild(field);
}
// A legend entry of at most LEGEND_CHARS characters (its middle elided; the hover names the
// solver, profile and instance in full): Plotly sizes the legend to its longest entry, and
// names of a solver, its parameters, a profile and an instance left the plot a sliver.
const LEGEND_CHARS = 44;
// A chart narrower than this (CSS pixels: a phone) puts its legend under the plot, not beside it.
const NARROW_CHART_PX = 600;
const legendName = n => typeof n === 'string' && n.length > LEGEND_CHARS
  ? n.slice(0, LEGEND_CHARS / 2 - 1) + '\u2026' + n.slice(n.length - LEGEND_CHARS / 2) : n;
// The legend entries of one chart: each elided, except those whose elided forms would read the
// same as another's (names that differ only in their middle), which keep their full names.
function legendNames(names) {
  const short = names.map(legendName), seen = new Map();
  short.forEach((s, i) => { if (s !== names[i]) seen.set(s, (seen.get(s) || 0) + 1); });
  const told = new Set(names.filter((n, i) => short[i] === n));
  return short.map((s, i) => s !== names[i] && (seen.get(s) > 1 || told.has(s)) ? names[i] : s);
}
// A legend under its plot starts LEGEND_GAP_PX below the x axis's tick labels and title.  Plotly puts
// it a share of the plot's height below the axis (legend.y), and on a plot made short by a long legend
// that share is less than the labels' own height: the legend's title sat on the axis title.  Once
// drawn, the legend moves down by what it lacks (or up by what it has to spare), and the plot shrinks (grows) by as much (the legend sets the
// bottom margin), so the share is taken of the plot's new height.
const LEGEND_GAP_PX = 6;
function lowestAxisText(div) {
  const boxes = [...div.querySelectorAll('.xtick text, .g-xtitle text')].map(e => e.getBoundingClientRect())
    .filter(b => b.height > 0);
  return boxes.length ? Math.max(...boxes.map(b => b.bottom)) : null;
}
async function legendBelowAxis(div) {
  for (let i = 0; i < 3; i++) {
    const lg = div.querySelector('.legend'), bottom = lowestAxisText(div), size = div._fullLayout._size;
    if (!lg || bottom === null) return;
    // (up as well: a legend a share of a grown plot's height below it left a wide empty band)
    const lack = bottom + LEGEND_GAP_PX - lg.getBoundingClientRect().top;
    if (Math.abs(lack) < 1 || size.h - lack < 1) return;
    await Plotly.relayout(div, {'legend.y': -(-div._fullLayout.legend.y * size.h + lack) / (size.h - lack)});
  }
}
// A chart whose legend goes under its plot grows by what the legend takes, so that its plot keeps the
// height it has in a chart of the CSS height (.chart) with its legend beside it: a long legend under a
// fixed-height chart left the plot a sliver.  ``base``: the chart's CSS height.
async function keepPlotHeight(div, base) {
  const m = div.layout.margin || {t: 40, b: 50};
  const normal = base - m.t - m.b;
  for (let i = 0; i < 6; i++) {  // the legend sits a share of the plot's height below it: a few rounds
    await legendBelowAxis(div);
    const lack = normal - div._fullLayout._size.h;  // (< 0: taller than it needs, never below the CSS height)
    if (Math.abs(lack) < 1 || (lack < 0 && div.clientHeight <= base)) return;
    div.style.height = Math.max(base, div.clientHeight + Math.ceil(lack)) + 'px';
    await Plotly.Plots.resize(div);
  }
  await legendBelowAxis(div);
}
// Draws every chart of the picked scenes; resolves once each is drawn and its legend placed.
function redraw() {
  document.querySelectorAll('section.scene').forEach(s => {
    if (s.dataset.scene) s.classList.toggle('hidden', !state.scenes.has(s.dataset.scene)); });
  const drawn = [];
  charts.forEach(c => {
    if (c.scene && !state.scenes.has(c.scene)) return;
    if (c.table) { c.table.render(); return; }
    const [traces, lay] = c.draw();
    const names = legendNames(traces.map(t => t.name));
    traces.forEach((t, i) => { t.name = names[i]; });
    const below = c.div.clientWidth < NARROW_CHART_PX;
    if (below) {  // a legend at the side would leave the plot a sliver
      lay.legend = Object.assign({}, lay.legend, {orientation: 'h', x: 0, xanchor: 'left', y: -0.32, yanchor: 'top'});
      if (lay.legend.title) lay.legend.title = Object.assign({}, lay.legend.title, {side: 'top'});
    }
    const div = c.div;
    div.style.height = '';  // the CSS height, grown again below where the legend goes under the plot
    const base = div.clientHeight;
    drawn.push(Plotly.react(div, traces, lay, {responsive: true, displayModeBar: false})
      .then(() => below ? keepPlotHeight(div, base) : null));
  });
  return Promise.all(drawn);
}
function checkbox(label, checked, onChange, swatch) {
  const l = document.createElement('label');
  const i = document.createElement('input'); i.type = 'checkbox'; i.checked = checked;
  i.addEventListener('change', () => onChange(i.checked));
  l.appendChild(i);
  if (swatch) { const s = document.createElement('span'); s.className = 'sw'; s.style.background = swatch; l.appendChild(s); }
  l.appendChild(document.createTextNode(label));
  return [l, i];
}
function picker() {
  const nav = document.getElementById('picker');
  const fsS = document.createElement('fieldset'); fsS.innerHTML = '<legend>scenes</legend>';
  D.scenes.forEach(s => fsS.appendChild(checkbox(s, true, on => { on ? state.scenes.add(s) : state.scenes.delete(s); redraw(); })[0]));
  const fsP = document.createElement('fieldset'); fsP.innerHTML = '<legend>profiles</legend>';
  D.profiles.forEach(p => fsP.appendChild(checkbox(p, true, on => { on ? state.profiles.add(p) : state.profiles.delete(p); redraw(); })[0]));
  const fsV = document.createElement('fieldset'); fsV.innerHTML = '<legend>solvers (a family box toggles the family)</legend>';
  D.families.forEach(f => {
    const boxes = [];
    const [fl, fi] = checkbox(f.name + ' (' + f.solvers.length + ')', true, on => {
      f.solvers.forEach(s => on ? state.solvers.add(s.name) : state.solvers.delete(s.name));
      boxes.forEach(b => { b.checked = on; }); redraw(); });
    fl.className = 'fam'; fi.dataset.family = f.name; fsV.appendChild(fl);
    f.solvers.forEach(s => { const [l, i] = checkbox(s.name, true, on => {
      on ? state.solvers.add(s.name) : state.solvers.delete(s.name);
      fi.checked = f.solvers.some(x => state.solvers.has(x.name)); redraw(); }, s.color);
      i.dataset.solver = s.name; boxes.push(i); fsV.appendChild(l); });
  });
  [fsS, fsP, fsV].forEach(x => nav.appendChild(x));
}
const t0 = performance.now();
picker();
build();
window.contactbenchReport = {state: state, charts: charts, redraw: redraw};
redraw().then(() => {
  window.contactbenchDrawMs = performance.now() - t0;
  document.body.dataset.ready = '1';
  let resized = null;  // a window of another width may move a legend between the side and the bottom
  window.addEventListener('resize', () => { clearTimeout(resized); resized = setTimeout(redraw, 200); });
});
})();
"""
