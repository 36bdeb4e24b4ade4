// pickplace operator's panel: REST for commands and history, one WebSocket for live state.
// One model (state.js) holds what the cell is; render() shows it everywhere at once.
import { describeAlarm } from "./alarms.js";
import { COLORS, JointPlot, drawCycleTrend, drawStageBars } from "./plot.js";
import { createRobotView } from "./robot3d.js";
import { applyStatusAnswer, cellState, createModel, robotBadge, stateClass } from "./state.js";

const API = "/api/v1";
const PAGE = 20;
const RECENT = 30; // picks in the cycle-time trend
const STAGE_PICKS = 10; // picks in the stage bars
const $ = (id) => document.getElementById(id);
const model = createModel();
const clock = (ms = Date.now()) => new Date(ms).toLocaleTimeString([], { hour12: false });

// ---------------------------------------------------------------- token and requests
// `pickplace up` prints http://127.0.0.1:8080/#token=…; the fragment never reaches the server.
function initToken() {
  const m = location.hash.match(/token=([^&]+)/);
  if (m) {
    sessionStorage.setItem("pickplace-token", decodeURIComponent(m[1]));
    history.replaceState(null, "", location.pathname);
  }
}
const token = () => sessionStorage.getItem("pickplace-token") || "";

function notice(text, kind = "error") {
  const n = $("notice");
  if (!text) { n.hidden = true; return; }
  n.textContent = text;
  n.className = kind === "info" ? "notice info" : "notice";
  n.hidden = false;
  clearTimeout(notice.timer);
  notice.timer = setTimeout(() => { n.hidden = true; }, kind === "info" ? 4000 : 10000);
}

async function api(path, { method = "GET", body } = {}) {
  const headers = { Accept: "application/json" };
  if (method !== "GET") {
    headers.Authorization = `Bearer ${token()}`;
    if (body !== undefined) headers["Content-Type"] = "application/json";
  }
  const res = await fetch(API + path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  let data = null;
  try { data = await res.json(); } catch { /* empty body */ }
  if (!res.ok) {
    const err = new Error((data && (data.detail || data.error)) || `${res.status} ${res.statusText}`);
    err.status = res.status;
    throw err;
  }
  return { data, res };
}

// ---------------------------------------------------------------- events timeline
const events = [];
// local: this page's own (commands, its link), kept when the gateway's timeline is replayed
function addEvent(text, cls = "idle", at = Date.now(), local = true) {
  events.unshift({ at, text, cls, local });
  if (events.length > 200) events.pop();
  renderEvents();
}
function renderEvents() {
  $("events").innerHTML = events.map((e) =>
    `<li class="${e.cls}"><time>${clock(e.at)}</time><span>${escapeHtml(e.text)}</span></li>`).join("");
}

let lastTaskState = null, lastMode = null, lastAlarms = new Set(), lastEstop = null;
function noteTask(t, at) {
  if (!t || t.state === lastTaskState) return;
  lastTaskState = t.state;
  const why = t.message ? ` — ${t.message}` : "";
  addEvent(`task ${t.state}${why}`, stateClass(t.state) === "ok" ? "idle" : stateClass(t.state), at, false);
}
function noteRobot(r, at) {
  if (!r) return;
  const add = (text, cls) => addEvent(text, cls, at, false);
  if (r.connected && r.robot_mode_name && r.robot_mode_name !== lastMode) {
    if (lastMode !== null) add(`robot mode ${lastMode} → ${r.robot_mode_name}`, stateClass(r.robot_mode_name));
    lastMode = r.robot_mode_name;
  }
  if (r.estop_active !== lastEstop) {
    if (r.estop_active) add("E-STOP active on the robot", "estop");
    else if (lastEstop) add("e-stop released", "ok");
    lastEstop = r.estop_active;
  }
  const now = new Set(r.alarms || []);
  for (const id of now) if (!lastAlarms.has(id)) add(`alarm ${id}: ${describeAlarm(id)}`, "bad");
  for (const id of lastAlarms) if (!now.has(id)) add(`alarm ${id} cleared`, "ok");
  lastAlarms = now;
}
// what a live message adds to the timeline; the gateway's timeline (sent first on connecting) replays
// the same messages with the time they happened, so a page opened later shows what went before
function noteMessage(msg, at = Date.now()) {
  const d = msg.data;
  switch (msg.type) {
    case "robot_status": noteRobot(d, at); break;
    case "task_status": noteTask(d, at); break;
    case "picks":
      for (const p of d) {
        if (p.success) continue; // the task's message often names the stage itself: said once
        const why = (p.error_message || p.error_code || "?").replace(new RegExp(`^${p.stage_reached}: `), "");
        addEvent(`pick #${p.id} failed at ${p.stage_reached}: ${why}`, "bad", at, false);
      }
      break;
    case "estop": addEvent(`E-STOP pressed: ${d.message}`, "estop", at, false); break;
    case "estop_task": addEvent(`e-stop: ${d.message}`, "warn", at, false); break;
    case "config": if (d.updated && d.updated.length) addEvent(`settings changed: ${d.updated.join(", ")}`, "idle", at, false); break;
    default: break;
  }
}
function replayTimeline(entries) {
  const local = events.filter((e) => e.local);
  events.length = 0;
  lastTaskState = null; lastMode = null; lastAlarms = new Set(); lastEstop = null;
  for (const m of entries) noteMessage(m, m.at_ms);
  events.push(...local);
  events.sort((a, b) => b.at - a.at);
  events.splice(200);
  renderEvents();
  $("events").dataset.replayed = String(entries.length);
}

// ---------------------------------------------------------------- render: one source of truth
function render() {
  const now = performance.now();
  const state = cellState(model, now);
  const cls = stateClass(state);
  $("state").textContent = state;
  $("state").className = cls;
  $("state-dot").className = `dot ${cls}`;
  const t = model.task;
  const fresh = t && now - model.taskAt <= 5000;
  $("cycle-progress").value = fresh ? t.progress || 0 : 0;
  $("cycle-text").textContent = fresh ? `#${t.cycle_index || 0} ${t.state}` : "task service not reporting";
  $("stat-task").textContent = fresh ? `${t.task || "—"} ${t.running ? "running" : "idle"} (${t.state})` : "offline";
  const b = robotBadge(model.robot);
  $("robot-mode").textContent = b.text;
  $("robot-mode").className = `badge ${b.cls}`;
  const g = $("gripper");
  if (model.robot && model.robot.connected && model.robot.gripper_closed != null) {
    g.textContent = model.robot.gripper_closed ? "closed" : "open";
    g.className = model.robot.gripper_closed ? "closed" : "open";
  }
  const st = model.status;
  if (st) {
    $("stat-uptime").textContent = fmtDuration(st.uptime);
    $("stat-db").textContent = st.database + (st.pick_buffer ? ` (${st.pick_buffer} buffered)` : "");
  }
}

// The live link: greyed out with "stale since" while neither the WebSocket nor the status answers.
function setLink(kind, up) {
  if (kind === "live") model.liveUp = up; else model.statusUp = up;
  const ok = model.liveUp && model.statusUp;
  if (ok) model.everUp = true;
  $("ws-state").textContent = `live: ${model.liveUp ? "connected" : "reconnecting…"}`;
  if (!ok && model.everUp && model.staleSince == null) {
    model.staleSince = Date.now();
    addEvent("live link to the gateway lost", "bad");
  } else if (ok && model.staleSince != null) {
    addEvent(`live link back (stale ${Math.round((Date.now() - model.staleSince) / 1000)} s)`, "ok");
    model.staleSince = null;
  }
  document.body.classList.toggle("stale", model.staleSince != null);
  document.body.dataset.stale = String(model.staleSince != null);
  const banner = $("stale");
  banner.hidden = model.staleSince == null;
  if (model.staleSince != null) {
    banner.textContent = `stale since ${clock(model.staleSince)}: no answer from the gateway; what is shown is ` +
      "the last known state (reconnecting by itself)";
  }
}

function fmtDuration(s) {
  if (s == null) return "—";
  const h = Math.floor(s / 3600), m = Math.floor((s % 3600) / 60), sec = Math.floor(s % 60);
  return h ? `${h}h ${m}m` : m ? `${m}m ${sec}s` : `${sec}s`;
}
const pct = (x) => (x == null ? "—" : `${(100 * x).toFixed(1)} %`);
const secs = (x) => (x == null ? "—" : `${x.toFixed(2)} s`);
function escapeHtml(s) {
  return String(s).replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" })[c]);
}

// ---------------------------------------------------------------- joints, TCP, force
const plot = new JointPlot($("joint-plot"));
let robotView = null;
function rpyDeg([qx, qy, qz, qw]) {
  const r = Math.atan2(2 * (qw * qx + qy * qz), 1 - 2 * (qx * qx + qy * qy));
  const p = Math.asin(Math.max(-1, Math.min(1, 2 * (qw * qy - qz * qx))));
  const y = Math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz));
  return [r, p, y].map((a) => ((a * 180) / Math.PI).toFixed(1));
}
function applyJoints(js) {
  model.joint = js;
  plot.push(js.source_stamp_ns || js.stamp_ns, js.position);
  if (robotView) robotView.setJoints(js.name, js.position);
  const rows = $("joint-rows");
  if (rows.children.length !== js.name.length) {
    rows.innerHTML = js.name.map((n, i) =>
      `<tr><th scope="row" style="color:${COLORS[i % COLORS.length]}">${n}</th>` +
      `<td data-testid="joint-${i + 1}"></td><td></td></tr>`).join("");
  }
  js.position.forEach((q, i) => {
    const tds = rows.children[i].children;
    tds[1].textContent = ((q * 180) / Math.PI).toFixed(2);
    tds[2].textContent = js.velocity.length ? ((js.velocity[i] * 180) / Math.PI).toFixed(1) : "";
  });
  if (js.tcp && js.tcp.length === 7) {
    $("tcp-pos").textContent = js.tcp.slice(0, 3).map((v) => (v * 1000).toFixed(1)).join("  ");
    $("tcp-rot").textContent = rpyDeg(js.tcp.slice(3)).join("  ");
  }
  if (js.force && js.force.length >= 3) {
    const [fx, fy, fz] = js.force;
    $("force").textContent = Math.hypot(fx, fy, fz).toFixed(1);
    $("force-xyz").textContent = [fx, fy, fz].map((f) => f.toFixed(1)).join("  ");
  }
}

// ---------------------------------------------------------------- camera and detections
let camView = "overlay", camSeq = 0, camPending = false, placeTargets = [];
function refreshCamera() {
  if (camPending) return;
  camPending = true;
  const img = $("camera-img");
  img.onload = () => { camPending = false; img.hidden = false; $("camera-none").hidden = true; img.dataset.view = camView; };
  img.onerror = () => { camPending = false; img.hidden = true; $("camera-none").hidden = false;
    $("camera-none").textContent = `no ${camView} image yet`; };
  img.src = `${API}/camera/latest.jpg?view=${camView}&seq=${camSeq}`;
}
function applyDetections(d) {
  model.detections = d;
  if (robotView) robotView.setDetections(d);
  const mm = (v) => (v ? v.map((x) => (x * 1000).toFixed(0)).join(" ") : "not calibrated");
  const rows = d.objects.map((o) => {
    const conf = o.kind === "rod" ? `${(100 * o.confidence).toFixed(0)} %`
      : o.kind === "cube" ? `fit ${o.fit_rms_mm.toFixed(1)} mm${o.visibility !== "whole" ? `, ${o.visibility}` : ""}`
        : (o.recognised ? "recognised" : "unknown object");
    const at = o.kind === "obstacle" && o.base ? `${mm(o.base[0])} → ${mm(o.base[1])}` : mm(o.base);
    return `<tr class="${o.kind}"><td>${o.kind}</td><td>${escapeHtml(o.color || "—")}</td>` +
      `<td class="conf">${conf}</td><td>${at}</td></tr>`;
  });
  $("det-rows").innerHTML = rows.join("") || `<tr><td colspan="4" class="muted">nothing detected</td></tr>`;
  $("det-info").textContent = `frame ${d.seq} · ${d.total_ms} ms`;
  $("det-notes").textContent = d.notes.join(" · ");
}

// ---------------------------------------------------------------- history, stats, trend, stages
let page = 0, total = 0;
async function loadHistory(highlight = new Set()) {
  try {
    const { data, res } = await api(`/picks?limit=${PAGE}&offset=${page * PAGE}`);
    total = Number(res.headers.get("X-Total-Count") || data.length);
    $("history-rows").innerHTML = data.map((p) => {
      const cls = (p.success ? "ok" : "fail") + (highlight.has(p.pick_id) ? " new" : "");
      const t = new Date(p.timestamp).toLocaleTimeString([], { hour12: false });
      const r = p.success ? "success" : p.outcome === "interrupted" ? "interrupted" : (p.error_code || "failed");
      return `<tr class="${cls}" title="${escapeHtml(p.error_message || "")}"><td>${p.id}</td><td>${t}</td>` +
             `<td>${escapeHtml(p.object_class || "—")}</td><td>${escapeHtml(r)}</td>` +
             `<td>${p.cycle_time == null ? "—" : p.cycle_time.toFixed(2)}</td><td>${escapeHtml(p.stage_reached || "")}</td></tr>`;
    }).join("") || `<tr><td colspan="6" class="muted">no picks yet</td></tr>`;
    const pages = Math.max(1, Math.ceil(total / PAGE));
    $("page-info").textContent = `page ${page + 1} of ${pages} · ${total} picks`;
    $("page-prev").disabled = page === 0;
    $("page-next").disabled = page + 1 >= pages;
  } catch (err) {
    $("page-info").textContent = `history unavailable: ${err.message}`;
  }
}

async function loadRecent() {
  try {
    const { data } = await api(`/picks?limit=${RECENT}`);
    $("trend").dataset.points = drawCycleTrend($("trend"), data);
    const details = await Promise.all(data.slice(0, STAGE_PICKS).map((p) => api(`/picks/${p.id}`).then((r) => r.data)));
    $("stages").dataset.bars = drawStageBars($("stages"), details);
  } catch { /* the history line says why */ }
}

async function loadStats() {
  try {
    const { data } = await api("/metrics");
    $("stat-success").textContent = pct(data.success_rate);
    $("stat-today").textContent = data.picks_today;
    $("stat-total").textContent = data.picks_total;
    $("stat-avg").textContent = secs(data.avg_cycle_time);
    $("stat-pct").textContent = data.cycle_time_p50 == null ? "—" :
      `${data.cycle_time_p50.toFixed(1)} / ${data.cycle_time_p95.toFixed(1)} s`;
  } catch { /* the status line shows the database state */ }
}

async function loadStatus() {
  const asked = performance.now();
  try {
    const st = (await api("/system/status")).data;
    applyStatusAnswer(model, st, asked, performance.now());
    noteRobot(model.robot); noteTask(model.task);
    setLink("status", true);
  } catch { setLink("status", false); }
  render();
}

// ---------------------------------------------------------------- live
function connectLive() {
  const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}${API}/live`);
  ws.onopen = () => { setLink("live", true); render(); };
  ws.onclose = () => { setLink("live", false); render(); setTimeout(connectLive, 1500); };
  ws.onmessage = (ev) => {
    const msg = JSON.parse(ev.data);
    switch (msg.type) {
      case "joint_state": applyJoints(msg.data); return;
      case "timeline": replayTimeline(msg.data); return;
      case "robot_status": model.robot = msg.data; model.robotAt = performance.now(); noteMessage(msg); break;
      case "task_status": model.task = msg.data; model.taskAt = performance.now(); noteMessage(msg); break;
      case "picks":
        page = 0;
        noteMessage(msg);
        loadHistory(new Set(msg.data.map((p) => p.pick_id))); loadStats(); loadRecent();
        break;
      case "camera": camSeq = msg.data.seq; refreshCamera(); loadCameraInfo(); return;
      case "plan": model.plan = msg.data; if (robotView) robotView.setPlan(msg.data); return;
      case "detections": applyDetections(msg.data); return;
      case "estop": noteMessage(msg); notice(`E-stop: ${msg.data.message}`); break;
      case "estop_task": noteMessage(msg); break;
      case "config": noteMessage(msg); loadConfig(); break;
      default: return;
    }
    render();
  };
}

// ---------------------------------------------------------------- controls
async function command(path, body, okText) {
  if (!token()) { $("token-dialog").showModal(); return; }
  try {
    const { data } = await api(path, { method: "POST", body });
    notice(okText || data.message, "info");
    addEvent(okText || data.message, "idle");
  } catch (err) {
    if (err.status === 401) { notice(`${err.message} — set the token`); $("token-dialog").showModal(); }
    else { notice(err.message); addEvent(`refused: ${err.message}`, "warn"); }
  }
  loadStatus();
}

// the camera's pinhole and calibrated pose, for the 3D view's frustum: once, asked again every 2 s
// until the camera has sent a frame
let cameraInfo = null, cameraInfoPending = false;
async function loadCameraInfo() {
  if (cameraInfo || !robotView || cameraInfoPending) return;
  cameraInfoPending = true;
  try {
    ({ data: cameraInfo } = await api("/camera/info"));
    robotView.setCamera(cameraInfo);
    cameraInfoPending = false;
  } catch {
    setTimeout(() => { cameraInfoPending = false; loadCameraInfo(); }, 2000);
  }
}

async function loadConfig() {
  try {
    const { data } = await api("/config");
    $("cell-id").textContent = `· ${data.cell_id} · ${data.robot.model}`;
    $("speed-range").value = data.robot.speed_ratio;
    $("speed-value").textContent = `${data.robot.speed_ratio} %`;
    const scene = data.sim && data.sim.twin && data.sim.twin.scene;
    if (scene) { // the place targets: where the rod is stood, where each cube colour goes
      placeTargets = [[...scene.rod_place_m, "white"],
        ...Object.entries(scene.drop_zones_m || {}).map(([c, xy]) => [...xy, c])];
      if (robotView) robotView.setTargets(placeTargets);
    }
  } catch { /* shown by status */ }
}

function bindControls() {
  $("btn-start").onclick = () => command("/system/start", { task: $("task-select").value, cycles: 0 });
  $("btn-stop").onclick = () => command("/system/stop");
  $("btn-estop").onclick = () => command("/system/estop", undefined, "E-stop sent to the robot");
  $("btn-reset").onclick = () => command("/system/estop/release");
  $("btn-token").onclick = () => { $("token-input").value = token(); $("token-dialog").showModal(); };
  $("token-dialog").addEventListener("close", () => {
    if ($("token-dialog").returnValue === "ok") sessionStorage.setItem("pickplace-token", $("token-input").value.trim());
  });
  $("page-prev").onclick = () => { if (page > 0) { page--; loadHistory(); } };
  $("page-next").onclick = () => { page++; loadHistory(); };
  $("camera").onclick = () => $("camera").classList.toggle("enlarged");
  for (const r of document.querySelectorAll('input[name="camview"]')) {
    r.onchange = () => { camView = r.value; camPending = false; refreshCamera(); };
  }
  $("speed-range").oninput = () => { $("speed-value").textContent = `${$("speed-range").value} %`; };
  $("speed-form").onsubmit = async (ev) => {
    ev.preventDefault();
    const v = Number($("speed-range").value);
    try {
      const { data } = await api("/config", { method: "PUT", body: { robot: { speed_ratio: v } } });
      notice(data.updated.length ? `speed ratio ${v} % applied` : `speed ratio already ${v} %`, "info");
    } catch (err) { notice(err.message); }
    loadConfig();
  };
}

async function main() {
  initToken();
  bindControls();
  loadConfig();
  connectLive();
  loadStatus(); loadHistory(); loadStats(); loadRecent();
  setInterval(loadStatus, 1000);
  setInterval(loadStats, 5000);
  setInterval(render, 1000); // a task that stops reporting goes stale even without new messages
  setInterval(() => { if (camView !== "overlay") { camSeq++; refreshCamera(); } }, 1000);
  robotView = await createRobotView($("robot3d"), `${API}/robot/urdf`);
  if (robotView) {
    robotView.setTargets(placeTargets);
    if (model.detections) robotView.setDetections(model.detections);
    if (model.plan) robotView.setPlan(model.plan);
    loadCameraInfo();
  }
}

main();
