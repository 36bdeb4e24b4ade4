"""Motion: robot models, kinematics, collision checking, planning and trajectories.

Modules (import what you need; heavy libraries load only with the modules that use them):

- ``robot_models``: DH tables and joint limits (``get_robot``, ``NOVA5``, ``UR5E``, ``UR3``).
- ``analytic``: closed-form FK/IK for the UR-structure arms (numpy only).
- ``trajectory``: ``JointTrajectory``, ``JointLimits``, quintic / min-jerk interpolation,
  key-pose cycles, limit verification (numpy/scipy only).
- ``timing``: time parameterisation with ruckig and TOPP-RA.
- ``cartesian``: straight tool lines with jump detection.
- ``urdf``: URDF text of each arm with its tool (``config/robots/*.urdf``).
- ``kinematics``: pinocchio models, FK, analytic and numerical IK.
- ``collision``: coal collision checking (self, table, boxes, attached object).
- ``sampling``: OMPL planners; ``planner``: the planning pipeline; ``service``: gRPC.
"""
