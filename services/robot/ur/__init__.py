"""A Universal Robots controller behind the driver's :class:`services.robot.link.ControllerLink`,
over SDU's ur_rtde (RTDE receive at 500 Hz, the control script, IO, the dashboard)."""
