"""Which samples the bus sends ahead: all but the high-rate streams."""

from __future__ import annotations

import zenoh

from services.common.bus import Bus
from services.common.keys import CellKeys, Lane, lane
from services.common.settings import Settings


def test_only_the_high_rate_streams_go_behind() -> None:
    keys = CellKeys("cell7")
    streams = {keys.joint_states, keys.camera_frames, keys.vision_debug_image}
    assert {lane(k) for k in streams} == {Lane.STREAM}
    records = [keys.pick_events, keys.pick_progress, keys.task_status, keys.task_commands, keys.robot_events]
    records += [keys.robot_status, keys.config_updates, keys.detected_objects, keys.task_plans]
    assert {lane(k) for k in records} == {Lane.AHEAD}
    # a cell whose id looks like a stream's tail changes nothing
    assert lane(CellKeys("camera").pick_events) is Lane.AHEAD


def test_a_pick_record_is_published_ahead_of_the_camera_and_never_blocks(settings: Settings) -> None:
    keys = CellKeys(settings.cell_id)
    with Bus(settings.zenoh) as bus:
        bus.publish(keys.pick_events, b"record")
        bus.publish(keys.camera_frames, b"frame")
        record, frame = bus._publishers[keys.pick_events], bus._publishers[keys.camera_frames]
        # nothing blocks the publisher's event loop (the driver's ServoJ stream runs on it)
        assert record.congestion_control == frame.congestion_control == zenoh.CongestionControl.DROP
        assert int(record.priority) < int(frame.priority)  # zenoh: a smaller number goes first
