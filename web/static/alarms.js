// Dobot controller alarm IDs and what they mean (services/dobot/codes.py ALARM_TEXT and describe_alarm;
// tests/web/test_dashboard_files.py keeps the two the same).
export const ALARM_TEXT = {
  16: "planned point near the shoulder singularity",
  17: "inverse kinematics has no solution",
  18: "IK result out of the working area",
  26: "near the wrist singularity",
  27: "near the elbow singularity",
  29: "speed parameter wrong",
  30: "full-parameter IK failed",
  115: "enable failed",
  116: "emergency stop button pressed",
  117: "collision detected",
};

export function describeAlarm(id) {
  if (id in ALARM_TEXT) return ALARM_TEXT[id];
  if (id >= 48 && id <= 53) return `joint ${id - 47} overspeed`;
  if (id >= 64 && id <= 75) {
    const j = Math.floor((id - 64) / 2), neg = (id - 64) % 2;
    return `joint ${j + 1} ${neg ? "negative" : "positive"} limit`;
  }
  return `alarm ${id}`;
}
