"""Defenses by name (`--defense NAME`): observation filters between the sensor and the policy."""

DEFENSES = ("kinematic",)
