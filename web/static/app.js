// pickplace dashboard: REST for commands and history, one WebSocket for live state.
import { COLORS, JointPlot } from "./plot.js";
import { createRobotView } from "./robot3d.js";

const API = "/api/v1";
const PAGE = 20;
const $ = (id) => document.getElementById(id);

// ---------------------------------------------------------------- token
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

// ---------------------------------------------------------------- state display
const STATE_CLASS = { DONE: "ok", IDLE: "ok", ESTOP: "bad", ERROR: "bad", ABORT: "bad", OFFLINE: "bad",
                      DETECT_FAILED: "warn", RETRY: "warn", STOPPED: "warn" };

function showState(state) {
  $("state").textContent = state;
  $("state-dot").className = "dot " + (STATE_CLASS[state] || "ok");
}

let lastStatus = null;
function applyStatus(st) {
  lastStatus = st;
  showState(st.state);
  const t = st.task;
  $("cycle-progress").value = t ? t.progress : 0;
  $("cycle-text").textContent = t ? `#${t.cycle_index} ${t.state}` : "task service offline";
  $("stat-task").textContent = t ? `${t.task || "—"} ${t.running ? "running" : "idle"}` : "offline";
  $("stat-uptime").textContent = fmtDuration(st.uptime);
  $("stat-db").textContent = st.database + (st.pick_buffer ? ` (${st.pick_buffer} buffered)` : "");
  applyRobot(st.robot);
}

function applyRobot(r) {
  const b = $("robot-mode");
  if (!r || !r.connected) { b.textContent = "offline"; b.className = "badge bad"; return; }
  if (r.estop_active) { b.textContent = "E-STOP"; b.className = "badge bad"; }
  else { b.textContent = r.robot_mode_name || String(r.robot_mode); b.className = "badge " + (r.enabled ? "ok" : "warn"); }
  if (r.estop_active) showState("ESTOP");
}

function fmtDuration(s) {
  if (s == null) return "—";
  const h = Math.floor(s / 3600), m = Math.floor((s % 3600) / 60), sec = Math.floor(s % 60);
  return h ? `${h}h ${m}m` : m ? `${m}m ${sec}s` : `${sec}s`;
}
const pct = (x) => (x == null ? "—" : `${(100 * x).toFixed(1)} %`);
const secs = (x) => (x == null ? "—" : `${x.toFixed(2)} s`);

// ---------------------------------------------------------------- joints
const plot = new JointPlot($("joint-plot"));
let robotView = null;
function applyJoints(js) {
  plot.push(js.stamp_ns, js.position);
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
}

// ---------------------------------------------------------------- history + stats
let page = 0, total = 0;
async function loadHistory(highlight = new Set()) {
  try {
    const { data, res } = await api(`/picks?limit=${PAGE}&offset=${page * PAGE}`);
    total = Number(res.headers.get("X-Total-Count") || data.length);
    $("history-rows").innerHTML = data.map((p) => {
      const cls = (p.success ? "ok" : "fail") + (highlight.has(p.pick_id) ? " new" : "");
      const t = new Date(p.timestamp).toLocaleTimeString();
      const res = p.success ? "success" : (p.error_code || "failed");
      return `<tr class="${cls}" title="${escapeHtml(p.error_message || "")}"><td>${p.id}</td><td>${t}</td>` +
             `<td>${escapeHtml(p.object_class || "—")}</td><td>${escapeHtml(res)}</td>` +
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

async function loadStats() {
  try {
    const { data } = await api("/metrics");
    $("stat-success").textContent = pct(data.success_rate);
    $("stat-today").textContent = data.picks_today;
    $("stat-total").textContent = data.picks_total;
    $("stat-avg").textContent = secs(data.avg_cycle_time);
    $("stat-pct").textContent = data.cycle_time_p50 == null ? "—" :
      `${data.cycle_time_p50.toFixed(1)} / ${data.cycle_time_p95.toFixed(1)} s`;
  } catch (err) { /* the status line shows the database state */ }
}

// A status answer must not undo a newer live message (the e-stop's robot_status can overtake it).
let liveRobotAt = 0;
async function loadStatus() {
  const asked = performance.now();
  try {
    const st = (await api("/system/status")).data;
    if (asked < liveRobotAt && lastStatus) st.robot = lastStatus.robot;
    applyStatus(st);
  } catch (err) { showState("OFFLINE"); }
}

function escapeHtml(s) {
  return String(s).replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" })[c]);
}

// ---------------------------------------------------------------- camera
let cameraPending = false, cameraSeq = 0;
function refreshCamera(seq) {
  cameraSeq = seq;
  if (cameraPending) return;
  cameraPending = true;
  const img = $("camera-img");
  img.onload = img.onerror = () => {
    cameraPending = false;
    img.hidden = false; $("camera-none").hidden = true;
  };
  img.src = `${API}/camera/latest.jpg?seq=${cameraSeq}`;
}

// ---------------------------------------------------------------- live
function connectLive() {
  const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}${API}/live`);
  ws.onopen = () => { $("ws-state").textContent = "live: connected"; };
  ws.onclose = () => {
    $("ws-state").textContent = "live: reconnecting…";
    setTimeout(connectLive, 1500);
  };
  ws.onmessage = (ev) => {
    const msg = JSON.parse(ev.data);
    switch (msg.type) {
      case "joint_state": applyJoints(msg.data); break;
      case "robot_status":
        liveRobotAt = performance.now();
        if (lastStatus) lastStatus.robot = msg.data;
        applyRobot(msg.data);
        if (!msg.data.estop_active && lastStatus && lastStatus.task) showState(lastStatus.task.state);
        break;
      case "task_status":
        if (lastStatus) { lastStatus.task = msg.data; }
        if (!lastStatus || !lastStatus.robot || !lastStatus.robot.estop_active) showState(msg.data.state);
        $("cycle-progress").value = msg.data.progress || 0;
        $("cycle-text").textContent = `#${msg.data.cycle_index || 0} ${msg.data.state}`;
        break;
      case "picks":
        page = 0;
        loadHistory(new Set(msg.data.map((p) => p.pick_id)));
        loadStats();
        break;
      case "camera": refreshCamera(msg.data.seq); break;
      case "estop": showState("ESTOP"); notice(`E-stop: ${msg.data.message}`); break;
      default: break;
    }
  };
}

// ---------------------------------------------------------------- controls
async function command(path, body, okText) {
  if (!token()) { $("token-dialog").showModal(); return; }
  try {
    const { data } = await api(path, { method: "POST", body });
    notice(okText || data.message, "info");
    loadStatus();
  } catch (err) {
    if (err.status === 401) { notice(`${err.message} — set the token`); $("token-dialog").showModal(); }
    else notice(err.message);
  }
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
}

async function main() {
  initToken();
  bindControls();
  try {
    const { data } = await api("/config");
    $("cell-id").textContent = `· ${data.cell_id} · ${data.robot.model}`;
  } catch { /* shown by status */ }
  connectLive();
  loadStatus(); loadHistory(); loadStats();
  setInterval(loadStatus, 2000);
  setInterval(loadStats, 5000);
  robotView = await createRobotView($("robot3d"), `${API}/robot/urdf`);
}

main();
