"""A simulated Universal Robots e-Series controller behind UR's own protocols (RTDE, dashboard,
script ports), driven by the kinematic engine; ur_rtde connects to it as to a real one."""
