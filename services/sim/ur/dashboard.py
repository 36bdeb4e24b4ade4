"""The simulated dashboard server's answers (pure): one request line → one reply line, in the words
of UR's Dashboard Server manual (docs/ur/rtde.md §3), acting on the :class:`URController`."""

from __future__ import annotations

from typing import TYPE_CHECKING

from services.rtde.codes import RuntimeState, SafetyMode
from services.rtde.dashboard import DashboardCommand as D
from services.rtde.dashboard import DashboardRequest, not_understood

if TYPE_CHECKING:
    from services.sim.ur.controller import URController

ROBOT_MODEL = {"ur5e": "UR5", "ur3": "UR3"}  # e-Series controllers answer the family name


def answer(c: URController, req: DashboardRequest, polyscope: str, serial: str) -> str:
    cmd = req.command
    if cmd is None:
        return not_understood(req.line)
    if cmd is D.ROBOTMODE:
        return f"Robotmode: {c.robot_mode.name}"
    if cmd is D.POWER_ON:
        if c.estop:
            return "Failed to execute: power on (emergency stop active)"
        c.power_on()
        return "Powering on"
    if cmd is D.POWER_OFF:
        c.power_off()
        return "Powering off"
    if cmd is D.BRAKE_RELEASE:
        if c.estop:
            return "Failed to execute: brake release (emergency stop active)"
        c.brake_release()
        return "Brake releasing"
    if cmd is D.UNLOCK_PROTECTIVE_STOP:
        why = c.unlock_protective_stop()
        return "Protective stop releasing" if why is None else why
    if cmd is D.CLOSE_SAFETY_POPUP:
        return "closing safety popup"
    if cmd is D.RESTART_SAFETY:
        if c.safety_mode in (SafetyMode.VIOLATION, SafetyMode.FAULT):
            c.safety_mode = SafetyMode.NORMAL
            c.power_off()
        return "Restarting safety"
    if cmd is D.PLAY:
        return "Starting program" if c.play() else "Failed to execute: play"
    if cmd is D.STOP:
        # "Stopped" with or without a program running: ur_rtde sends stopScript then "stop" when it
        # replaces a running script and raises unless it reads exactly this (its CI runs on URSim)
        c.stop_program("dashboard stop")
        return "Stopped"
    if cmd is D.PAUSE:
        return "Failed to execute: pause"  # a script program cannot be paused from the dashboard
    if cmd is D.RUNNING:
        return f"Program running: {str(c.runtime_state is RuntimeState.PLAYING).lower()}"
    if cmd is D.PROGRAM_STATE:
        name = c.program.name if c.program is not None else "<unnamed>"
        state = "PLAYING" if c.runtime_state is RuntimeState.PLAYING else "STOPPED"
        return f"{state} {name}"
    if cmd is D.SAFETYSTATUS:
        return f"Safetystatus: {c.safety_mode.name}"
    if cmd is D.SAFETYMODE:
        return f"Safetymode: {c.safety_mode.name}"
    if cmd is D.IS_IN_REMOTE_CONTROL:
        return str(c.config.remote_control).lower()
    if cmd is D.POLYSCOPE_VERSION:
        return polyscope
    if cmd is D.GET_SERIAL_NUMBER:
        return serial
    if cmd is D.GET_ROBOT_MODEL:
        return ROBOT_MODEL.get(c.spec.name, c.spec.name.upper())
    if cmd is D.GET_LOADED_PROGRAM:
        return "No program loaded"
    if cmd is D.IS_PROGRAM_SAVED:
        return "false <unnamed>"
    if cmd in (D.CLOSE_POPUP,):
        return "closing popup"
    if cmd is D.POPUP:
        return "showing popup"
    if cmd is D.ADD_TO_LOG:
        c.note(f"log: {req.argument}")
        return "Added log message"
    if cmd is D.LOAD:
        return f"File not found: {req.argument}"
    if cmd is D.QUIT:
        return "Disconnected"
    if cmd is D.SHUTDOWN:
        return "Shutting down"
    return not_understood(req.line)
