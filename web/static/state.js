// The cell's state as the dashboard shows it: one model, one rule (the gateway's, gateway/status.py),
// one colour per meaning. Every panel reads from here; nothing else decides what the state is.

export const TASK_FRESH_MS = 5000; // the task service reports at 2 Hz; older than this it is gone

const RUNNING = new Set(["INIT", "DETECT", "PLAN", "APPROACH", "GRASP", "LIFT", "REORIENT", "TRANSPORT",
  "PLACE", "RELEASE", "DONE", "RETRY", "ENABLE", "RUNNING", "SINGLE_MOVE", "ENABLED"]);
const FAULT = new Set(["ERROR", "ALARM", "ABORT", "OFFLINE", "COLLISION", "DETECT_FAILED", "FAILED"]);
const HALTED = new Set(["STOPPED", "PAUSE", "DISABLED", "POWER_OFF", "BRAKE_OPEN", "BACKDRIVE"]);

// "estop" flashes red; "bad" is red (errors, alarms, offline); "ok" green (enabled, running);
// "warn" amber (stopped, disabled, paused); "idle" neutral.
export function stateClass(state) {
  const s = String(state || "").toUpperCase();
  if (s === "ESTOP" || s === "E-STOP") return "estop";
  if (FAULT.has(s)) return "bad";
  if (RUNNING.has(s)) return "ok";
  if (HALTED.has(s)) return "warn";
  return "idle";
}

export function createModel() {
  return {
    task: null, taskAt: 0, // the task service's last status and when it was true (ms, performance.now)
    robot: null, robotAt: 0,
    status: null, // the last /system/status (uptime, database, buffer)
    joint: null,
    detections: null,
    liveUp: false, statusUp: false, everUp: false, staleSince: null,
  };
}

// The gateway's rule: e-stop first; then the task's state while it reports; else whether the robot answers.
export function cellState(model, now) {
  const r = model.robot;
  if (r && r.estop_active) return "ESTOP";
  if (model.task && now - model.taskAt <= TASK_FRESH_MS) return model.task.state || "UNKNOWN";
  return r && r.connected ? "IDLE" : "OFFLINE";
}

// What the robot badge says: E-STOP, ALARM (with codes), the controller's mode name, or offline.
export function robotBadge(robot) {
  if (!robot || !robot.connected) return { text: "offline", cls: "bad" };
  if (robot.estop_active) return { text: "E-STOP", cls: "estop" };
  if (robot.alarms && robot.alarms.length && robot.robot_mode_name !== "ENABLE") {
    return { text: robot.robot_mode_name === "ERROR" ? "ERROR" : "ALARM", cls: "bad" };
  }
  const name = robot.robot_mode_name || String(robot.robot_mode);
  return { text: name, cls: stateClass(name) };
}

// A status answer asked before a newer live message must not undo it.
export function applyStatusAnswer(model, st, askedAt, now) {
  model.status = st;
  if (askedAt >= model.robotAt) { model.robot = st.robot; model.robotAt = askedAt; }
  if (st.task && askedAt >= model.taskAt) {
    model.task = st.task;
    model.taskAt = now - 1000 * (st.task.age_s || 0);
  }
}
