"""Universal Robots' RTDE, dashboard and script-port protocols, sans-I/O: used by the simulated UR
controller (and by tests that speak the wire themselves). ``codes`` holds the enums, ``fields`` the
variable types, ``codec`` the packages and recipes, ``dashboard`` the line protocol, ``script`` the
program framer, ``poses`` UR's pose vectors. Facts and sources: docs/ur/rtde.md."""
