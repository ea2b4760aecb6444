"""Breakaway (Stribeck) friction on the MuJoCo plant (issue 30): MuJoCo's dry friction plus an assist.

MuJoCo's joints have a dry ``frictionloss``: a constraint that holds the joint while the other forces
on it stay below the level and slides at the level above. The MJCF's values are the lumped sliding
levels ``d_c`` (mujoco_model.py: ``d_cl = frictionloss_fl + frictionloss_rl``, ``d_cw`` per wheel). A run
whose plant settings have breakaway (:meth:`agvdyn.simulation.plant.PlantSettings.group_breakaway`,
some group's ratio != 1) gets the friction law of our plant and of the model's Stribeck term
(:func:`agvdyn.model_spec.joint_friction`) per joint ``j`` of group ``g`` (l: steer_fl, steer_rl;
r: steer_fr, steer_rr; w: the four wheels), with ``d_s = ratio_g d_c`` and ``w_s`` the group's
Stribeck velocity:

* :func:`breakaway_friction` raises the joint's ``model.dof_frictionloss`` to the static level
  ``ratio_g * frictionloss_j`` (the constraint holds the joint below it: a stuck joint breaks away at
  ``d_s``), on the run's compiled model; the MJCF text, its hash and the lumped parameters stay the
  vehicle's. MuJoCo's friction constraint is soft: with the default ``solreffriction`` (0.02 s, 1) and
  ``solimpfriction`` (0.9, 0.95) a wheel under 0.8 of the level creeps at ~0.04 rad/s (measured,
  lifted wheel, d_c = 3.97 N m), as fast as the Stribeck velocities of the studies, and the creep
  feeds the assist: a wheel at 0.97 d_s broke away. The breakaway joints therefore get a stiff
  friction constraint, :data:`STICK_SOLREF` (time constant 2 timesteps, MuJoCo's smallest) and
  :data:`STICK_SOLIMP` (impedance 0.99): creep ~4e-4 rad/s at 0.8-0.97 d_s, a wheel at 1.03 d_s
  breaks away (our plant: 1e-4 rad/s below ``ratio d_c``);
* :meth:`BreakawayFriction.assist` sets, before each sample's MuJoCo steps, the generalised force
  (MuJoCo's ``qfrc_applied``: positive along the joint's positive direction, added to the motors' and
  the constraints' forces)

      qfrc_applied[j] = (ratio_g - 1) frictionloss_j (1 - exp(-(w_j / w_s)^2)) sign(w_j)

  with ``w_j`` the joint's velocity at the sample: an assist along the motion, so that a joint sliding
  at ``w`` feels ``ratio d_c - (ratio - 1) d_c (1 - e) = d_c + (d_s - d_c) exp(-(w / w_s)^2)``
  against it (``e = exp(-(w/w_s)^2)``). The assist is below the static level (``(ratio - 1) d_c <
  ratio d_c``): the net friction stays dissipative. It is held over the sample's steps (2 ms; w_s
  of the studies >= 0.02 rad/s).

Without breakaway nothing is changed or set: the run is bit-identical to one without this module.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agvdyn.platform import WHEELS

__all__ = ["BreakawayFriction", "breakaway_friction", "BREAKAWAY_JOINTS", "STICK_SOLREF", "STICK_SOLIMP"]

#: Friction constraint of the breakaway joints: time constant (in model timesteps) and damping ratio,
#: and MuJoCo's solimp (d0, d_width, width, midpoint, power): a joint stuck below d_s creeps at ~4e-4 rad/s.
STICK_SOLREF = (2.0, 1.0)
STICK_SOLIMP = (0.99, 0.99, 0.001, 0.5, 2.0)

#: MuJoCo joints of each breakaway group, in the order of PlantSettings.group_breakaway (l, r, w).
BREAKAWAY_JOINTS = (("steer_fl", "steer_rl"), ("steer_fr", "steer_rr"), tuple(f"wheel_{w}" for w in WHEELS))


@dataclass(frozen=True, eq=False)
class BreakawayFriction:
    """The breakaway joints of one MuJoCo run: their degrees of freedom ``dofs`` (n,), the assist's
    peak ``excess = (ratio - 1) frictionloss`` (n,) N m and the Stribeck velocities ``w_s`` (n,) rad/s."""

    dofs: np.ndarray
    excess: np.ndarray
    w_s: np.ndarray

    def assist_torques(self, w: np.ndarray) -> np.ndarray:
        """The assist ``excess (1 - exp(-(w / w_s)^2)) sign(w)`` (N m) at joint rates ``w`` (..., n)."""
        w = np.asarray(w, dtype=float)
        return self.excess * -np.expm1(-np.square(w / self.w_s)) * np.sign(w)

    def assist(self, qvel: np.ndarray, qfrc_applied: np.ndarray) -> None:
        """Write the assist at MuJoCo's velocities ``qvel`` into ``qfrc_applied`` (its joints' rows only)."""
        qfrc_applied[self.dofs] = self.assist_torques(qvel[self.dofs])


def _dof(model, joint: str, source: str) -> int:
    """The degree of freedom of ``joint`` in ``model``; ValueError naming ``source`` when it has none."""
    import mujoco

    i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint)
    if i < 0:
        raise ValueError(f"{source}: no joint named {joint!r}: expected agvdyn's vehicle model (breakaway friction "
                         f"acts on the joints {[j for group in BREAKAWAY_JOINTS for j in group]})")
    return int(model.jnt_dofadr[i])


def breakaway_friction(model, plant_settings, source: str = "model", *, solref: tuple[float, float] = STICK_SOLREF,
                       solimp: tuple[float, ...] = STICK_SOLIMP) -> BreakawayFriction | None:
    """Put the static friction levels of the breakaway groups of ``plant_settings`` into ``model``
    (``dof_frictionloss`` *= ratio, and the stiff friction constraint ``solref`` (time constant in
    timesteps, damping ratio) / ``solimp``, in place) and return the assist; None (the model untouched) when
    every group's ratio is 1. ValueError (naming ``source``) for a model without agvdyn's joint names."""
    dofs, excess, w_s = [], [], []
    for (ratio, speed), joints in zip(plant_settings.group_breakaway(), BREAKAWAY_JOINTS):
        if ratio == 1.0:
            continue
        for name in joints:
            dof = _dof(model, name, source)
            sliding = float(model.dof_frictionloss[dof])
            model.dof_frictionloss[dof] = ratio * sliding
            model.dof_solref[dof] = (solref[0] * model.opt.timestep, solref[1])
            model.dof_solimp[dof] = solimp
            dofs.append(dof)
            excess.append((ratio - 1.0) * sliding)
            w_s.append(speed)
    if not dofs:
        return None
    return BreakawayFriction(np.array(dofs, dtype=np.int64), np.array(excess), np.array(w_s))
