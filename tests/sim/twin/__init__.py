"""Tests of the twin's per-trial worlds (services/sim/twin)."""
