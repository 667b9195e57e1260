"""Gymnasium v5 Walker2d on MJX: `gymnasium/envs/mujoco/walker2d_v5.py` with its default arguments
(walker2d_v5.xml, both feet friction 0.9 as in v5).

Hopper's observation and reward (`adarl.device.hopper.planar_rules`): observation ``qpos[1:]``
then ``clip(qvel, -10, 10)`` (17 numbers); reward ``x_velocity + healthy - 1e-3 * sum(action**2)``;
healthy: ``0.8 < z < 2`` and ``-1 < angle < 1`` (no state range); reset noise ``U(-5e-3, 5e-3)``
on qpos and qvel; frame skip 4.
"""

from __future__ import annotations

from adarl.device.hopper import planar_rules

HEALTHY_Z_RANGE = (0.8, 2.0)
HEALTHY_ANGLE_RANGE = (-1.0, 1.0)

RULES = planar_rules("walker2d", "walker2d_v5.xml", 6, 9, 9, HEALTHY_Z_RANGE, HEALTHY_ANGLE_RANGE)
