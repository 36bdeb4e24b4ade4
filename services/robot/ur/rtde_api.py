"""The ur_rtde objects of one UR link and every blocking call made on them.

Called from the link's worker thread (``open``, ``close``, commands) and its poller thread
(``sample``); ``async_status`` is a quick GIL-releasing read the loop thread may make. Nothing here
knows asyncio. ur_rtde ships no type stubs: its modules are typed ``Any`` at this one boundary.
"""

from __future__ import annotations

import contextlib
import threading
import time
from typing import Any

from services.robot.ur.feedback import RECEIVE_VARIABLES, URSample

PROGRAM_START_TIMEOUT_S = 5.0  # ur_rtde's own wait for its script (waitForProgramRunning)
CONSISTENT_READ_TRIES = 5
CONTROL_SELF_RECONNECT_S = 0.5  # ur_rtde's control interface reconnecting itself after a loss


def _modules() -> tuple[Any, Any, Any]:
    import dashboard_client  # type: ignore[import-not-found]
    import rtde_control  # type: ignore[import-not-found]
    import rtde_receive  # type: ignore[import-not-found]

    return dashboard_client, rtde_receive, rtde_control


# ur_rtde objects whose disconnect failed (the peer was gone): their C++ destructors disconnect
# again and would throw out of a destructor (std::terminate, the whole process), so they are kept
# alive instead — a few small objects per lost link, never destroyed.
_UNDESTROYABLE: list[Any] = []


def _quiet_disconnect(obj: Any) -> None:
    try:
        obj.disconnect()
    except RuntimeError:
        _UNDESTROYABLE.append(obj)


class Interfaces:
    def __init__(self) -> None:
        self.host = ""
        self.frequency_hz = 500.0
        self.db: Any = None
        self.receive: Any = None
        self.control: Any = None

    def open(self, host: str, frequency_hz: float) -> None:
        """Dashboard, receive and IO; the control interface waits for ``ensure_control`` (its script
        runs only on a powered arm with released brakes)."""
        dashboard_client, rtde_receive, _ = _modules()
        self.host, self.frequency_hz = host, frequency_hz
        db = dashboard_client.DashboardClient(host)
        db.connect()
        self.db = db
        self.receive = rtde_receive.RTDEReceiveInterface(host, frequency_hz, RECEIVE_VARIABLES)

    def close(self, graceful: bool = True) -> None:
        """Disconnect the receive interface and the dashboard (side by side: each ur_rtde disconnect
        sleeps 500 ms). ``graceful`` (a sound link, the link closing) also stops the control script and
        disconnects the control interface. After a loss the control interface is left alone: its own
        receive thread reconnects it (ur_rtde's receiveCallback) and disconnecting it meanwhile races
        that thread inside ur_rtde (a segfault, seen in tests/robot/ur); ``ensure_control`` takes it
        back, or sets it aside, once that attempt is over."""
        objs = [o for o in (self.receive, self.db) if o is not None]
        self.receive = self.db = None
        if graceful and self.control is not None:
            control, self.control = self.control, None
            with contextlib.suppress(RuntimeError):
                if control.isConnected() and control.isProgramRunning():
                    control.stopScript()
            objs.append(control)
        threads = [threading.Thread(target=_quiet_disconnect, args=(o,), name="ur-disconnect") for o in objs]
        for t in threads:
            t.start()
        for t in threads:
            t.join()

    def ensure_control(self) -> None:
        _, _, rtde_control = _modules()
        if self.control is not None and not self.control.isConnected():
            # a lost link: give ur_rtde's own reconnect its chance, then set a dead interface aside
            deadline = time.monotonic() + CONTROL_SELF_RECONNECT_S
            while not self.control.isConnected() and time.monotonic() < deadline:
                time.sleep(0.01)
            if not self.control.isConnected():
                _UNDESTROYABLE.append(self.control)  # its thread has given up; its destructor may throw
                self.control = None
        if self.control is None:
            self.control = rtde_control.RTDEControlInterface(self.host, self.frequency_hz)
        elif not self.control.isProgramRunning() and not self.control.reuploadScript():
            raise RuntimeError("the control script could not be re-uploaded")
        deadline = time.monotonic() + PROGRAM_START_TIMEOUT_S
        while not self.control.isProgramRunning():
            if time.monotonic() > deadline:
                raise RuntimeError(
                    f"ur_rtde's control script is not running after {PROGRAM_START_TIMEOUT_S:.0f}s"
                )
            time.sleep(0.002)

    # ------------------------------------------------------------------ feedback
    def sample(self, last_timestamp_s: float) -> URSample | None:
        """The newest sample, None when it is still the one stamped ``last_timestamp_s``."""
        r = self.receive
        if r is None or not r.isConnected():
            raise RuntimeError("the RTDE receive interface is disconnected")
        for _ in range(CONSISTENT_READ_TRIES):
            ts = r.getTimestamp()
            if ts == last_timestamp_s:
                return None
            s = URSample(
                timestamp_s=ts,
                q=tuple(r.getActualQ()),
                qd=tuple(r.getActualQd()),
                q_target=tuple(r.getTargetQ()),
                tcp_pose=tuple(r.getActualTCPPose()),
                tcp_force=tuple(r.getActualTCPForce()),
                robot_mode=int(r.getRobotMode()),
                safety_mode=int(r.getSafetyMode()),
                safety_status_bits=int(r.getSafetyStatusBits()),
                runtime_state=int(r.getRuntimeState()),
                digital_inputs=int(r.getActualDigitalInputBits()),
                digital_outputs=int(r.getActualDigitalOutputBits()),
                received_ns=time.time_ns(),
            )
            if r.getTimestamp() == ts:  # no newer package landed while the fields were read
                return s
        return s

    def async_status(self) -> tuple[bool, int] | None:
        c = self.control
        if c is None:
            return None
        st = c.getAsyncOperationProgressEx()
        return bool(st.isAsyncOperationRunning()), int(st.operationId())

    # ------------------------------------------------------------------ commands
    def _control(self) -> Any:
        if self.control is None:
            raise RuntimeError("ur_rtde's control script is not running: enable the robot first")
        return self.control

    def move(self, name: str, q: list[float], v: float, a: float) -> tuple[bool, int]:
        c = self._control()
        ok = bool(getattr(c, name)(q, v, a, True))
        return ok, int(c.getAsyncOperationProgressEx().operationId())

    def control_call(self, name: str, *args: Any) -> Any:
        return getattr(self._control(), name)(*args)

    def servo(self, q: list[float], t_s: float, lookahead_s: float, gain: float) -> tuple[bool, float]:
        """servoJ, and the controller's clock (s) right after it returned: read from the receive
        interface, which ur_rtde's own thread keeps current however busy Python is."""
        ok = bool(self._control().servoJ(q, 0.0, 0.0, t_s, lookahead_s, gain))
        r = self.receive
        return ok, float(r.getTimestamp()) if r is not None else 0.0

    def dashboard(self, command: str) -> str:
        if self.db is None:
            raise RuntimeError("the dashboard is not connected")
        self.db.send(command + "\n")
        return str(self.db.receive())

    def stop(self, decel: float) -> None:
        c = self.control
        if c is None or not c.isProgramRunning():
            return
        c.servoStop(decel)
        c.speedStop(decel)
        c.stopJ(decel, False)
