"""Live updates for the dashboard (WebSocket), the latest camera image, the robot's URDF."""

from __future__ import annotations

import asyncio
import contextlib

from fastapi import APIRouter, HTTPException, Response, WebSocket, WebSocketDisconnect
from google.protobuf.message import DecodeError

from gateway.camera import CameraView, frame_intrinsics, frame_jpeg, sensor_frame_jpeg
from gateway.contract import errors
from gateway.deps import CellDep
from gateway.live import encode
from gateway.schemas import CameraInfo
from services.common.camera_pose import load_T_base_camera
from services.common.errors import InvalidInputError
from services.common.settings import CONFIG_DIR

router = APIRouter(tags=["live"])

PING_INTERVAL_S = 15.0
PING = encode({"type": "ping", "data": {}})


@router.websocket("/live")
async def live(ws: WebSocket) -> None:
    """Messages ``{"type": "task_status"|"joint_state"|"robot_status"|"picks"|"camera"|"estop"|…, "data": …}``.

    The current state first, then every change; joint states at ``gateway.joint_state_rate_hz``.
    """
    cell = ws.app.state.cell
    await ws.accept()
    with cell.hub.connection() as queue:
        reader = asyncio.create_task(_drain_client(ws))
        try:
            while not reader.done():
                try:
                    async with asyncio.timeout(PING_INTERVAL_S):
                        text = await queue.get()
                except TimeoutError:
                    text = PING
                await ws.send_text(text)
        except (WebSocketDisconnect, RuntimeError):
            pass
        finally:
            reader.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await reader


async def _drain_client(ws: WebSocket) -> None:
    """The browser sends nothing we need; reading notices when it goes away."""
    with contextlib.suppress(WebSocketDisconnect, RuntimeError):
        while True:
            await ws.receive_text()


@router.get(
    "/camera/latest.jpg",
    response_class=Response,
    responses={
        200: {"content": {"image/jpeg": {"schema": {"type": "string", "format": "binary"}}}},
        **errors(404, 422),
    },
)
async def camera(cell: CellDep, view: CameraView = CameraView.OVERLAY) -> Response:
    """The camera panel's image: ``overlay`` the vision service's debug image (detections drawn on it),
    ``color`` / ``depth`` the camera's newest frame (depth as a colour map, black where none)."""
    hub = cell.hub
    if view is CameraView.OVERLAY:
        if hub.camera_jpeg is None:
            raise HTTPException(404, "no camera image received yet (vision service not publishing)")
        jpeg = hub.camera_jpeg
    else:
        payload, frame = hub.frame_payload, hub.frame_object
        if payload is None and frame is None:
            raise HTTPException(404, "no camera frame received yet (camera not publishing)")
        key = (view, hub.frame_count)
        cached = hub.view_cache
        if cached is not None and cached[0] == key:
            jpeg = cached[1]
        else:
            try:
                if frame is not None:
                    jpeg = await asyncio.to_thread(sensor_frame_jpeg, frame, view)
                else:
                    assert payload is not None
                    jpeg = await asyncio.to_thread(frame_jpeg, payload, view)
            except (InvalidInputError, DecodeError) as exc:
                raise HTTPException(404, f"the newest camera frame cannot be shown: {exc}") from exc
            hub.view_cache = (key, jpeg)
    return Response(jpeg, media_type="image/jpeg", headers={"Cache-Control": "no-store"})


@router.get("/camera/info", response_model=CameraInfo, responses=errors(404))
async def camera_info(cell: CellDep) -> CameraInfo:
    """The camera for the 3D view's frustum: the newest frame's pinhole, and the camera's pose in the
    base frame as vision takes it (the calibration file, else the manual pose). 404 before a frame."""
    hub = cell.hub
    payload, frame = hub.frame_payload, hub.frame_object
    try:
        if frame is not None:
            k = frame.intrinsics
        elif payload is not None:
            k = await asyncio.to_thread(frame_intrinsics, payload)
        else:
            raise HTTPException(404, "no camera frame received yet (camera not publishing)")
    except (InvalidInputError, DecodeError) as exc:
        raise HTTPException(404, f"the newest camera frame has no usable intrinsics: {exc}") from exc
    T, source = load_T_base_camera(cell.settings.vision.calibration)
    return CameraInfo(
        width=k.width,
        height=k.height,
        fx=k.fx,
        fy=k.fy,
        cx=k.cx,
        cy=k.cy,
        T_base_camera=None if T is None else [[round(float(v), 6) for v in row] for row in T],
        pose_source=source,
    )


@router.get(
    "/robot/urdf",
    response_class=Response,
    responses={200: {"content": {"application/xml": {"schema": {"type": "string"}}}}, **errors(404)},
)
async def robot_urdf(cell: CellDep) -> Response:
    """The URDF of the configured robot model, for the dashboard's 3D view."""
    model = cell.settings.robot.model
    path = CONFIG_DIR / "robots" / f"{model}.urdf"
    if not path.exists():
        raise HTTPException(404, f"no URDF for robot model {model!r} at {path}")
    return Response(path.read_text(), media_type="application/xml")
