"""The Dobot V4 TCP/IP protocol, sans-I/O: used by the robot driver and by the simulated controller."""
