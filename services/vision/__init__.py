"""Vision: the objects on the table from RGB-D frames, and the camera-to-base calibration.

Pure cores (numpy/OpenCV/scikit-learn, no I/O): ``geometry`` (back-projection, RANSAC table
plane), ``rod`` (seed 001 rod detector), ``cubes`` (seed 004 RANSAC + DBSCAN cubes and obstacle
boxes), ``pose`` (LLD §3.4.1 PCA pose), ``pipeline`` (one frame → ``DetectionResult``),
``overlay`` (debug JPEG), ``calibration`` and ``board`` (manual and eye-to-hand calibration with a
ChArUco board), ``synthetic`` (seeded ray-cast test scenes with ground truth).
Shells: ``camera`` (the Camera protocol), ``realsense``, ``replay`` (sources and the recorder),
``calibrate_workflow`` (the robot-driven calibration run), ``service`` (gRPC + Zenoh + metrics).

Kept import-free: the twin imports ``services.common.sensors`` and must not pull in the detectors.
"""
