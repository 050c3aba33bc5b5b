// The dashboard page: draws the frames the server pushes over /ws and sends teach/cancel/save.
"use strict";
(function () {
  const CHANNELS = ["right_thigh", "left_thigh", "right_shank", "left_shank"];
  const COLOURS = ["#c62828", "#1565c0", "#ef6c00", "#6a1b9a"];
  const STATE_TEXT = { walking: "walking", stand: "standing", unknown: "unknown", not_ready: "not ready" };
  const KEPT = 3000;
  const $ = (id) => document.getElementById(id);
  const token = new URLSearchParams(location.search).get("token");
  const live = { frames: 0, points: 0, kernels: {}, library: "", note: "", rows: [], taught: [], estimate: null, readOnly: false };
  window.gaitDashboard = live; // what the browser test reads, with what the page shows

  // -- chart: 4 angle series (solid) and the kernel at the estimated phase (dashed)
  const series = [{ label: "s before the last sample" }];
  CHANNELS.forEach((c, i) => series.push({ label: c, stroke: COLOURS[i], width: 2 }));
  CHANNELS.forEach((c, i) => series.push({ label: c + " kernel", stroke: COLOURS[i], width: 1.5, dash: [6, 4] }));
  const chart = new uPlot({
    width: Math.max(300, $("chart").clientWidth), height: 300, series: series,
    scales: { x: { time: false } }, axes: [{ label: "s before the last sample" }, { label: "deg" }], legend: { show: false },
  }, [[], [], [], [], [], [], [], [], []], $("chart"));

  function kernelAt(kernel, phase, ch) {
    const s = kernel.samples, n = s.length;
    const x = (((phase % 1) + 1) % 1) * n, i = Math.floor(x) % n, f = x - Math.floor(x);
    return s[i][ch] * (1 - f) + s[(i + 1) % n][ch] * f;
  }

  function drawChart() {
    const rows = live.rows, e = live.estimate;
    if (!rows.length) { chart.setData([[], [], [], [], [], [], [], [], []]); live.points = 0; return; }
    const taught = e && live.taught.includes(e.mode); // the file's kernel is not the node's any more
    const kernel = e && e.state === "walking" && !taught ? live.kernels[e.mode] : undefined;
    let stride = kernel ? kernel.samples.length / kernel.rate_hz : 1.2;
    if (e && e.phase_rate && e.phase_rate > 0.2) stride = 1 / e.phase_rate;
    const last = rows[rows.length - 1][0];
    const shown = rows.filter((r) => r[0] >= last - stride);
    const data = [shown.map((r) => r[0] - last)];
    for (let c = 0; c < 4; c++) data.push(shown.map((r) => r[c + 1]));
    for (let c = 0; c < 4; c++) {
      data.push(kernel && e.phase !== null ? data[0].map((x) => kernelAt(kernel, e.phase + x / stride, c)) : data[0].map(() => null));
    }
    chart.setData(data);
    live.points = shown.length;
    $("kernel-name").textContent = kernel ? e.mode + " kernel" : taught ? "kernel (" + e.mode + " taught on the node: not shown)" : "kernel";
  }

  // -- panels
  function fmt(v, digits) { return v === null || v === undefined ? "–" : v.toFixed(digits); }

  function drawEstimate(e) {
    const box = $("state-box");
    const state = e ? e.state : "not_ready";
    box.className = "state " + state;
    $("mode").textContent = e && e.mode ? e.mode : "–";
    $("state").textContent = STATE_TEXT[state];
    $("phase").textContent = fmt(e && e.phase, 2);
    $("phase-fill").style.width = e && e.phase !== null ? (100 * e.phase).toFixed(1) + "%" : "0";
    $("numbers").textContent = e ? "confidence " + fmt(e.confidence, 2) + " · cadence " +
      (e.phase_rate ? (60 * e.phase_rate).toFixed(0) + " strides/min" : "–") + " · fit " + fmt(e.fit_rms_deg, 1) + " deg rms" : "";
    const errors = $("errors");
    if (!e) { errors.textContent = "no estimate yet"; return; }
    const finite = e.sse.filter((m) => m[1] !== null).map((m) => m[1]);
    const top = Math.max(1e-9, ...finite);
    const best = finite.length ? Math.min(...finite) : null;
    errors.replaceChildren(...e.sse.map(([name, v]) => {
      const row = document.createElement("div"); row.className = "bar-row";
      const label = document.createElement("span"); label.textContent = name;
      const bar = document.createElement("div"); bar.className = "bar" + (v !== null && v === best ? " best" : "");
      bar.style.width = v === null ? "0" : Math.max(1, 100 * v / top).toFixed(1) + "%";
      const value = document.createElement("span"); value.textContent = fmt(v, 1);
      row.append(label, bar, value); return row;
    }));
  }

  function drawDiagnostics(d) {
    $("diag-level").textContent = d.level || "no diagnostics yet";
    $("diag-level").className = "level " + d.level;
    $("diag-message").textContent = d.message;
    const rejected = Object.entries(d.rejected).map(([k, v]) => k + " " + v).join(", ");
    const rows = [["input rate", d.input_rate_hz ? d.input_rate_hz + " Hz" : "–"],
      ["samples", (d.samples_received || "–") + " received, " + (d.samples_rejected || "0") + " rejected"],
      ["rejected by reason", rejected || "none"], ["window", d.window || "–"],
      ["IMU calibration", d.imu_calibration_status ? d.imu_calibration_status + (d.imu_calibration ? " (" + d.imu_calibration + ")" : "") : "no IMU input"],
      ["sensor offsets (deg)", d.sensor_offset_deg || "–"], ["library", d.library || "–"]];
    $("diag").replaceChildren(...rows.map(([k, v]) => {
      const tr = document.createElement("tr"); const a = document.createElement("td"); const b = document.createElement("td");
      a.textContent = k; b.textContent = v; tr.append(a, b); return tr;
    }));
    const t = d.teach;
    live.taught = t.taught_modes ? t.taught_modes.split(",") : [];
    $("teach-progress").textContent = t.mode ? t.mode + " " + t.progress : "not teaching";
    $("teach-result").textContent = t.last_result ? "last kernel: " + t.last_result : "";
  }

  function addLog(lines) {
    if (!lines.length) return;
    const pre = $("teach-log");
    pre.textContent = (pre.textContent + lines.join("\n") + "\n").split("\n").slice(-40).join("\n");
    pre.scrollTop = pre.scrollHeight;
  }

  function onFrame(f) {
    live.frames++;
    $("link").className = "banner " + f.link.status;
    $("link").textContent = f.link.text;
    for (const r of f.angles) live.rows.push(r);
    if (live.rows.length && f.angles.length && live.rows.length > f.angles.length &&
        live.rows[live.rows.length - f.angles.length - 1][0] > f.angles[0][0]) live.rows = f.angles.slice(); // stamps went back: a new stream
    if (live.rows.length > KEPT) live.rows.splice(0, live.rows.length - KEPT);
    live.estimate = f.estimate;
    live.link = f.link.status;
    drawEstimate(f.estimate);
    drawDiagnostics(f.diagnostics);
    addLog(f.log);
    drawChart();
  }

  function onKernels(k) {
    live.kernels = k.modes; live.library = k.library; live.note = k.note;
    $("kernel-note").textContent = k.library ? "kernels: library '" + k.library + "'" + (k.note ? "; " + k.note : "") : k.note;
    $("mode-list").replaceChildren(...Object.keys(k.modes).map((m) => { const o = document.createElement("option"); o.value = m; return o; }));
  }

  // -- socket (reconnects: the dashboard may restart)
  let ws = null;
  function connect() {
    const url = (location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws" + (token ? "?token=" + encodeURIComponent(token) : "");
    ws = new WebSocket(url);
    ws.onmessage = (ev) => {
      const m = JSON.parse(ev.data);
      if (m.type === "frame") onFrame(m);
      else if (m.type === "kernels") onKernels(m);
      else if (m.type === "hello") {
        live.readOnly = m.read_only;
        $("read-only").hidden = !m.read_only;
        $("teach-form").hidden = m.read_only;
      } else if (m.type === "reply") { $("reply").textContent = (m.ok ? "" : "✗ ") + m.text; live.reply = m; }
    };
    ws.onclose = () => {
      $("link").className = "banner offline";
      $("link").textContent = "dashboard server not reachable: reconnecting…";
      setTimeout(connect, 1000);
    };
  }
  function send(msg) { if (ws && ws.readyState === 1) ws.send(JSON.stringify(msg)); }
  $("teach-form").addEventListener("submit", (ev) => {
    ev.preventDefault();
    send({ op: "teach", mode: $("teach-mode").value.trim(), strides: parseInt($("teach-strides").value, 10) });
  });
  $("teach-cancel").addEventListener("click", () => send({ op: "cancel" }));
  $("teach-save").addEventListener("click", () => send({ op: "save" }));
  connect();
})();
