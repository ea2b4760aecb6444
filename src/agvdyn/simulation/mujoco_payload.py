"""Payload events on the MuJoCo plant (issue 31 item 4): the loads as a body welded to the chassis.

A run with payload events (``SimulationSettings.payload``) compiles the vehicle's MJCF with one more
body, ``payload`` (:data:`agvdyn.simulation.mujoco_model.PAYLOAD_BODY`), a child of ``chassis`` without
a joint and without mass (:func:`payload_model`; ``mujoco.MjSpec``, for a generated MJCF and a file
alike: the MJCF text, its hash and the file written beside the log stay those of the vehicle). Without
a load it adds exact zeros to MuJoCo's composite inertias: until the first event the run is
bit-identical to the one without payload events (tests/test_mujoco_payload.py).

Before the first sample of each event the body gets the sums of the events so far, the same as on
our plant (:func:`agvdyn.simulation.payload.payload_state`): mass ``m_p``, centre ``S / m_p`` at the
height of the chassis' centre of mass, yaw inertia ``J_p - |S|^2 / m_p`` about it
(:func:`payload_inertial`); ``mujoco.mj_setConst`` then recomputes
the constants that depend on the masses (subtree masses, the inverse weights that scale the contact
softness) on a scratch ``MjData`` (it overwrites the state of the data it is given). ``qpos`` and
``qvel`` are left as they are: the velocities are continuous through the event, as on our plant.
Events at t = 0 are loaded before the contacts settle (the run starts at rest with the load on).

Energy: the kinetic energy jumps by ``1/2 qvel^T (M' - M) qvel`` (the truth's ``energy_jump``) and the
potential energy by the load's weight times its height. Neither is work of the motors: from each
event on, the potential-energy column of the stepper's ``energy`` holds MuJoCo's potential energy
less both jumps so far, so that the dissipated work ``simulate`` derives (motor work less the change of
kinetic plus potential energy) stays the dissipation, and the power balance of our plant's test
(kinetic energy change + dissipated work = motor work + the kinetic jumps) holds on MuJoCo too.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from agvdyn.simulation.mujoco_model import PAYLOAD_BODY
from agvdyn.simulation.payload import PayloadEvent, PayloadTruth, payload_state, split_at_events

__all__ = ["payload_inertial", "payload_model", "set_payload_body", "MujocoPayload"]


def payload_inertial(moments: np.ndarray, height: float = 0.0) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass (kg), centre (3,) in the chassis frame (m) and principal moments (3,) about that centre
    (kg m^2) of the body ``payload`` that carries the loads ``moments = (m_p, S_x, S_y, J_p)`` (their
    sums, :func:`agvdyn.simulation.payload.payload_state`; ``J_p`` about the reference point):

        m_p,   (S_x / m_p, S_y / m_p, height),   C_zz = J_p - (S_x^2 + S_y^2) / m_p,   C_xx = C_yy = C_zz / 2

    (parallel axis; roll and pitch those of a flat load, the perpendicular-axis theorem: the events give
    only the yaw inertia). ``m_p < 0`` (more dropped than picked up: the chassis' own mass) is a body of
    negative mass, which the chassis' outweighs (checked by the caller). ``m_p = 0`` with first moments
    ``S`` = 0 is a yaw inertia ``J_p`` at the reference point; with ``S`` != 0 no one body has it: ValueError.

    Examples
    --------
    >>> m, c, I = payload_inertial(np.array([200.0, 40.0, -20.0, 50.0]))
    >>> m, c.tolist(), I.tolist()
    (200.0, [0.2, -0.1, 0.0], [20.0, 20.0, 40.0])
    """
    m_p, s_x, s_y, j_p = (float(v) for v in moments)
    if abs(m_p) <= 1e-12 * max(1.0, abs(j_p)):
        if math.hypot(s_x, s_y) > 1e-12:
            raise ValueError(f"payload moments (m_p, S_x, S_y, J_p) = {(m_p, s_x, s_y, j_p)}: no mass but a first "
                             "moment (a load dropped elsewhere than picked up): expected the drops where the loads are")
        return 0.0, np.array([0.0, 0.0, height]), np.array([j_p / 2, j_p / 2, j_p])
    c_zz = j_p - (s_x ** 2 + s_y ** 2) / m_p
    return m_p, np.array([s_x / m_p, s_y / m_p, height]), np.array([c_zz / 2, c_zz / 2, c_zz])


def payload_model(xml: str, source: str) -> Any:
    """The compiled ``mujoco.MjModel`` of the MJCF ``xml`` with the massless body ``payload`` welded to
    its ``chassis`` (the last body). ValueError (naming ``source``) when the MJCF has no body ``chassis``
    or already a body ``payload``."""
    import mujoco

    try:
        spec = mujoco.MjSpec.from_string(xml)
    except ValueError as exc:
        raise ValueError(f"{source}: MuJoCo cannot load the MJCF: {exc}") from exc
    chassis = spec.body("chassis")
    if chassis is None:
        raise ValueError(f"{source}: no body named 'chassis': expected agvdyn's vehicle model")
    if spec.body(PAYLOAD_BODY) is not None:
        raise ValueError(f"{source}: has a body named {PAYLOAD_BODY!r}: expected none (payload events add it, "
                         "welded to the chassis); rename it")
    chassis.add_body(name=PAYLOAD_BODY)
    return spec.compile()


def set_payload_body(model: Any, body: int, moments: np.ndarray, height: float, scratch: Any) -> None:
    """Give body ``body`` of ``model`` the loads ``moments = (m_p, S_x, S_y, J_p)`` (payload_inertial at
    ``height``) in place, and recompute the model's mass-dependent constants (``mj_setConst`` on the
    ``MjData`` ``scratch``, whose state it overwrites)."""
    import mujoco

    mass, centre, inertia = payload_inertial(moments, height)
    model.body_mass[body] = mass
    model.body_ipos[body] = centre
    model.body_iquat[body] = (1.0, 0.0, 0.0, 0.0)
    model.body_inertia[body] = inertia
    model.body_sameframe[body] = 0  # the centre is off the body frame: MuJoCo must not skip it
    mujoco.mj_setConst(model, scratch)


def _loaded_inertia(model: Any, chassis: int, moments: np.ndarray, height: float) -> np.ndarray:
    """Eigenvalues of the inertia tensor of chassis body plus payload about their common centre of mass."""
    import mujoco

    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, model.body_iquat[chassis])
    R = R.reshape(3, 3)
    own = R @ np.diag(model.body_inertia[chassis]) @ R.T
    parts = [(float(model.body_mass[chassis]), model.body_ipos[chassis], own)]
    mass, centre, inertia = payload_inertial(moments, height)
    parts.append((mass, centre, np.diag(inertia)))
    total = sum(m for m, _, _ in parts)
    com = sum(m * c for m, c, _ in parts) / total
    I = sum(J + m * (np.dot(c - com, c - com) * np.eye(3) - np.outer(c - com, c - com)) for m, c, J in parts)
    return np.linalg.eigvalsh(I)


class MujocoPayload:
    """The payload events of one MuJoCo run: planned at construction (ValueError for a load the chassis
    body cannot carry), then :meth:`load_at_rest` (the events at sample 0, before the contacts settle)
    and :meth:`stepper` (the others, between samples). Each applied event's
    :class:`~agvdyn.simulation.payload.PayloadTruth` joins ``truths``."""

    def __init__(self, model: Any, m_ch: float, C_ch: float, events: tuple[PayloadEvent, ...], sample_time: float,
                 energy: np.ndarray, truths: list) -> None:
        import mujoco

        self.model, self.energy, self.truths, self.sample_time = model, energy, truths, sample_time
        self.body = int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, PAYLOAD_BODY))
        chassis = int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "chassis"))
        if self.body < 0 or chassis < 0 or model.body_parentid[self.body] != chassis:
            raise ValueError(f"model without a body {PAYLOAD_BODY!r} on the chassis: compile it with payload_model")
        self.height = float(model.body_ipos[chassis][2])
        self.plan = payload_state(events, m_ch, C_ch, float(model.body_mass[chassis]), sample_time)
        self.order = sorted(events, key=lambda e: e.t)
        for ev, (_, moments, *_) in zip(self.order, self.plan):
            low = _loaded_inertia(model, chassis, moments, self.height).min()
            if not low > 0:
                raise ValueError(f"payload at t = {ev.t} s: the loaded chassis body's smallest principal inertia "
                                 f"would be {low:.6g} kg m^2 (the load's roll and pitch: half its yaw inertia): "
                                 "expected a smaller drop")
        self.scratch = mujoco.MjData(model)
        self.jumps = 0.0  # kinetic and potential energy the events applied during the run added (J)
        self.done = 0

    def _apply(self, i: int, data: Any) -> tuple[float, float]:
        """Load event i; the jumps (kinetic, potential) of MuJoCo's energy at the state of ``data``."""
        import mujoco

        mujoco.mj_forward(self.model, data)
        before = data.energy.copy()
        set_payload_body(self.model, self.body, self.plan[i][1], self.height, self.scratch)
        mujoco.mj_forward(self.model, data)
        k, _, m, C, xc, yc = self.plan[i]
        jump_k, jump_u = float(data.energy[1] - before[1]), float(data.energy[0] - before[0])
        self.truths.append(PayloadTruth(self.order[i], k, k * self.sample_time, float(m), float(C), float(xc),
                                        float(yc), jump_k))
        return jump_k, jump_u

    def load_at_rest(self, data: Any) -> None:
        """Load the events of sample 0 (call before the contacts settle: their energy jumps are 0)."""
        while self.done < len(self.plan) and self.plan[self.done][0] == 0:
            self._apply(self.done, data)  # at rest: no kinetic energy jump
            self.done += 1

    def stepper(self, step: Callable[[int, int], None], data: Any) -> Callable[[int, int], None]:
        """``step(k0, k1)`` of the run with the remaining events loaded before their first samples and
        the potential-energy column of ``energy`` less the jumps so far (module docstring)."""
        first = self.done

        def corrected(k0: int, k1: int) -> None:
            step(k0, k1)
            if self.jumps != 0.0:
                self.energy[k0:k1, 1] -= self.jumps

        def apply(i: int) -> None:
            jump_k, jump_u = self._apply(first + i, data)
            self.jumps += jump_k + jump_u

        return split_at_events(corrected, [p[0] for p in self.plan[first:]], apply)
