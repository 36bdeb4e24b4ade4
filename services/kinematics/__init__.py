"""The shared robot library, pure (no I/O beyond reading the robot description files).

- ``robot_models``: DH tables and joint limits (``get_robot``, ``NOVA5``, ``UR5E``, ``UR3``).
- ``analytic``: closed-form FK/IK for the UR-structure arms (numpy only), the entry point; its parts:
  ``chain`` (the joint chain and its FK), ``closed_form`` (one pose), ``closed_form_batch`` (many poses).
- ``model``: pinocchio models of each arm with its tool, FK, Jacobians, analytic and numerical IK.
- ``urdf``: URDF text of each arm with its tool (``config/robots/*.urdf``).
- ``tool``: the tool geometry and TCP frame built from settings (``tool_geometry``, ``tool_frame``).
- ``cartesian``: straight tool lines with jump detection.
- ``poses``: pose validation and display helpers.
- ``trajectory``: ``JointTrajectory``, ``JointLimits``, interpolation, and the independent limit check.
- ``collision``: coal collision model of the arm, table, boxes and an attached object.

Used by every service that reasons about the arm (grasp, motion, robot driver, task, simulator).
"""
