"""The hexapod plant block's parameters and ports: the same in every engine.

Units SI; joint vectors leg-major (leg 0 ``alpha, beta, gamma``, leg 1 ..., leg 5):

============== ===== ===== =========================================================================
port           dir   shape meaning
============== ===== ===== =========================================================================
q_target       in    18    joint position targets of the servos (rad)
q              out   18    joint angles (rad)
qd             out   18    joint velocities (rad/s)
toe_force      out   18    per leg ``(Fx lateral, Fy forward, Fz vertical)`` in the BODY frame: the
                           force the ground exerts on the foot (``Fz > 0`` when standing), N
body_position  out   3     body frame origin (centre of the body box) in the world, m
body_rpy       out   3     ``(roll, pitch, yaw)`` with ``R = Rz(yaw) Rx(pitch) Ry(roll)``, rad
foot_position  out   18    foot sphere centres in the world frame, m
body_contact   out   1     1 when the body box touched anything during the last step (boolean)
============== ===== ===== =========================================================================

Roll turns about the forward axis ``y`` (positive: right side down), pitch about the lateral axis
``x`` (positive: nose up), yaw about ``z`` (positive: turning left). No output reads an input in
the same step (no direct feedthrough). The outputs are one vector from the compiled readout
(:mod:`cpgsim.robots.readout`), in ``OUTPUT_PORTS`` order; ``PORT_SLICES`` cuts it into ports.
"""

from __future__ import annotations

import math

from cpgsim.components.core import CoSimBlock
from cpgsim.robots.description import default_gains

OUTPUT_PORTS = (("q", 18), ("qd", 18), ("toe_force", 18), ("body_position", 3), ("body_rpy", 3),
                ("foot_position", 18), ("body_contact", 1))
"""The plant's output ports in the order of the readout vector, with their sizes."""


def _slices() -> dict[str, slice]:
    out, k = {}, 0
    for name, size in OUTPUT_PORTS:
        out[name] = slice(k, k + size)
        k += size
    return out


FLOAT32_OUTPUTS = frozenset({"q", "qd", "toe_force", "body_position", "body_rpy", "foot_position"})
"""The outputs a results file stores as float32 (:attr:`CoSimBlock.float32_outputs`): the engine's measurements,
whose own error (the engine's time step alone moves them by 1e-4 to 1e-1 of their range) is orders above
float32's rounding (2^-24 of the value); tests/test_results_float32.py measures both per column. The body
contact flag stays float64 (it is 0 or 1; nothing to gain)."""

PORT_SLICES: dict[str, slice] = _slices()
"""Each output port's slice of the readout vector."""
READOUT_SIZE = sum(size for _, size in OUTPUT_PORTS)


def declare_plant(block: CoSimBlock) -> None:
    """The hexapod plant's parameters and ports: servo gains, friction, the joint targets in, and joint angles
    and velocities, toe forces, body pose, feet and body contact out."""
    block.float32_outputs = FLOAT32_OUTPUTS
    kp, kd = default_gains(block.geometry)
    block.add_parameter("kp", kp, "N*m/rad", (0.0, math.inf), "joint servo stiffness", strict=True)
    block.add_parameter("kd", kd, "N*m*s/rad", (0.0, math.inf), "joint servo damping", strict=True)
    block.add_parameter("friction", 1.0, "1", (0.0, math.inf), "Coulomb friction of the robot's shapes",
                        strict=True)
    block.add_parameter("velocity_ff", 0.0, "1", (0.0, 1.0), "advance the servo rest position by "
                        "kd/kp * target velocity", kind="boolean")
    block.add_input("q_target", 18, "rad",
                    description="joint position targets, leg-major (alpha, beta, gamma)")
    block.add_output("q", 18, "rad", description="joint angles, leg-major")
    block.add_output("qd", 18, "rad/s", description="joint velocities, leg-major")
    block.add_output("toe_force", 18, "N", description="ground force on each foot "
                     "(Fx lateral, Fy forward, Fz vertical) in the body frame")
    block.add_output("body_position", 3, "m", description="body origin in the world frame")
    block.add_output("body_rpy", 3, "rad", description="roll (about y), pitch (about x), yaw (about z)")
    block.add_output("foot_position", 18, "m", description="foot centres in the world frame, leg-major")
    block.add_output("body_contact", 1, "1", kind="boolean",
                     description="1 when the body box touched anything during the last step")
