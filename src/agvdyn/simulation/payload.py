"""Payload changes of the simulated vehicle: loads picked up and dropped during a run (issue 31).

A :class:`PayloadEvent` at time ``t`` (s) adds a rigid body of ``mass`` kg (negative: a drop of that
much) whose centre is at ``(x, y)`` m in the chassis frame (PLATFORM.md: origin at the centre of the
steering axes) and whose yaw inertia about its own centre is ``inertia`` kg m^2 (of the body picked
up or dropped: a drop subtracts it). From the first sample at or after ``t`` the chassis carries the
sum of the events so far: mass ``m_p = sum m_i``, first moments ``S = sum m_i (x_i, y_i)`` and yaw
inertia about the reference point ``J_p = sum (C_i + m_i (x_i^2 + y_i^2))`` (parallel axis). The
plant (plant.py, "Payload") adds them to the chassis; the true parameters become

    m_ch' = m_ch + m_p,   C_ch' = C_ch + J_p  (about the reference point),
    (x_c, y_c) = S / m_ch'  (centre of mass of the loaded chassis; the unloaded one at the origin),

and the yaw inertia about the loaded centre of mass is ``C_ch' - m_ch' (x_c^2 + y_c^2)``. The tyres'
normal load becomes ``m_ch' g / 4`` (the load distribution of an off-centre payload is not modelled).
A payload carried through the whole run (every event at t = 0) makes these the log's truth: the
sidecar's ``true_parameters`` hold m_ch', C_ch' and x_c, y_c (``SimulationResult.true_model``, the
``com_offset`` extension of :mod:`agvdyn.model_spec`).

The velocities are continuous through an event (the load is handed over at the vehicle's velocity),
so the kinetic energy jumps by ``1/2 v^T (M' - M) v``: :attr:`PayloadTruth.energy_jump`, and the
power balance of the run holds with these jumps added (tests/test_simulation.py).

Command line: ``--payload T:MASS[:X,Y[:C]]`` (:func:`parse_payload`); sidecar ``payload_truth``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["PayloadEvent", "PayloadTruth", "parse_payload", "payload_state", "payload_from_list", "split_at_events"]


def _finite(where: str, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{where}{key}={value!r}: expected a finite number")
    return float(value)


@dataclass(frozen=True)
class PayloadEvent:
    """Pick-up (``mass`` > 0) or drop (``mass`` < 0) of a load at time ``t`` s, centre ``(x, y)`` m in the
    chassis frame, yaw inertia ``inertia`` kg m^2 about its own centre (>= 0; a drop removes it)."""

    t: float
    mass: float
    x: float = 0.0
    y: float = 0.0
    inertia: float = 0.0

    def __post_init__(self) -> None:
        where = "payload: "
        for key in ("t", "mass", "x", "y", "inertia"):
            object.__setattr__(self, key, _finite(where, key, getattr(self, key)))
        if self.t < 0:
            raise ValueError(f"{where}t={self.t!r}: expected a time >= 0 s")
        if self.mass == 0:
            raise ValueError(f"{where}mass=0: expected a pick-up (> 0 kg) or a drop (< 0 kg)")
        if self.inertia < 0:
            raise ValueError(f"{where}inertia={self.inertia!r}: expected >= 0 kg m^2 (a drop removes it)")

    @property
    def sign(self) -> float:
        return 1.0 if self.mass > 0 else -1.0

    def moments(self) -> np.ndarray:
        """(m, m x, m y, C sign + m (x^2 + y^2)): what the event adds to (m_p, S_x, S_y, J_p)."""
        m = self.mass
        return np.array([m, m * self.x, m * self.y, self.sign * self.inertia + m * (self.x ** 2 + self.y ** 2)])

    def to_dict(self) -> dict[str, float]:
        return {"t": self.t, "mass": self.mass, "x": self.x, "y": self.y, "inertia": self.inertia}


def parse_payload(text: str) -> PayloadEvent:
    """``T:MASS[:X,Y[:C]]`` -> :class:`PayloadEvent` (``"12.5:300:0.2,-0.1:40"``); a bad string is a
    ValueError naming it and the expected form."""
    form = "expected T:MASS[:X,Y[:C]] (time s, mass kg (negative: drop), offset m in the chassis frame, " \
           "yaw inertia kg m^2 about the load's centre), e.g. 20:300:0.2,0:45"
    parts = text.strip().split(":")
    try:
        if not 2 <= len(parts) <= 4:
            raise ValueError("wrong number of fields")
        t, mass = float(parts[0]), float(parts[1])
        x = y = 0.0
        if len(parts) >= 3:
            xy = parts[2].split(",")
            if len(xy) != 2:
                raise ValueError("the offset needs X,Y")
            x, y = float(xy[0]), float(xy[1])
        inertia = float(parts[3]) if len(parts) == 4 else 0.0
    except ValueError as exc:
        raise ValueError(f"--payload {text!r}: {exc}: {form}") from None
    try:
        return PayloadEvent(t, mass, x, y, inertia)
    except ValueError as exc:
        raise ValueError(f"--payload {text!r}: {str(exc).split(': ', 1)[1]}") from None


def payload_from_list(data: Any, source: str = "<settings>") -> tuple[PayloadEvent, ...]:
    """Events from a settings file's ``payload: [{t, mass, x, y, inertia}, ...]`` (None: none)."""
    if data is None:
        return ()
    if not isinstance(data, list):
        raise ValueError(f"{source}: payload={data!r}: expected a list of mappings {{t, mass, x, y, inertia}}")
    out = []
    for n, item in enumerate(data):
        allowed = set(PayloadEvent.__dataclass_fields__)
        if not isinstance(item, dict) or set(item) - allowed:
            raise ValueError(f"{source}: payload[{n}]={item!r}: expected a mapping with keys among {sorted(allowed)}")
        try:
            out.append(PayloadEvent(**item))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{source}: payload[{n}]: {exc}") from exc
    return tuple(out)


@dataclass(frozen=True)
class PayloadTruth:
    """The vehicle after one event: the sample it applies from (``t_applied``), the true chassis
    parameters (``m_ch``, ``C_ch`` about the reference point, centre of mass ``x_c``, ``y_c``, yaw
    inertia ``C_ch_centre`` about it) and the kinetic energy jump ``energy_jump`` (J)."""

    event: PayloadEvent
    sample: int
    t_applied: float
    m_ch: float
    C_ch: float
    x_c: float
    y_c: float
    energy_jump: float

    @property
    def C_ch_centre(self) -> float:
        return self.C_ch - self.m_ch * (self.x_c ** 2 + self.y_c ** 2)

    def to_dict(self) -> dict[str, float]:
        return {**self.event.to_dict(), "t_applied": self.t_applied, "m_ch": self.m_ch, "C_ch": self.C_ch,
                "x_c": self.x_c, "y_c": self.y_c, "C_ch_centre": self.C_ch_centre, "energy_jump": self.energy_jump}


def payload_state(events: tuple[PayloadEvent, ...], m_ch: float, C_ch: float, body_mass: float,
                  sample_time: float) -> list[tuple[int, np.ndarray, float, float, float, float]]:
    """For each event in time order: (first sample k with t_k >= t, cumulative (m_p, S_x, S_y, J_p),
    m_ch', C_ch', x_c, y_c). Raises ValueError when the loaded chassis would weigh less than its
    body (``body_mass``: chassis minus steering units) or its yaw inertia about its centre of mass
    would be <= 0 (more dropped than was picked up)."""
    total = np.zeros(4)
    out = []
    for ev in sorted(events, key=lambda e: e.t):
        total = total + ev.moments()
        k = int(math.ceil(ev.t / sample_time - 1e-9))
        m = m_ch + total[0]
        if body_mass + total[0] <= 0:
            raise ValueError(f"payload at t = {ev.t} s: the chassis would weigh {m:.6g} kg in all, less than its "
                             f"steering units: expected a smaller drop")
        C = C_ch + total[3]
        xc, yc = total[1] / m, total[2] / m
        if C - m * (xc ** 2 + yc ** 2) <= 0:
            raise ValueError(f"payload at t = {ev.t} s: the loaded chassis' yaw inertia about its centre of mass "
                             f"would be {C - m * (xc ** 2 + yc ** 2):.6g} kg m^2: expected a smaller drop")
        out.append((k, total.copy(), m, C, xc, yc))
    return out


def payload_stepper(step: Any, c: np.ndarray, pos: np.ndarray, vel: np.ndarray, events: tuple[PayloadEvent, ...],
                    m_ch: float, C_ch: float, sample_time: float, truths: list) -> Any:
    """``step(k0, k1)`` of a closed loop split at the samples of ``events``: before the first sample of
    each event the payload in the plant constants ``c`` (in place) becomes the sum so far, and its
    :class:`PayloadTruth` (with the kinetic energy jump at the state ``pos``, ``vel``) joins ``truths``."""
    from agvdyn.simulation._kernels import kinetic_energy
    from agvdyn.simulation.plant import _MB, set_payload

    plan = payload_state(events, m_ch, C_ch, float(c[_MB]), sample_time)
    order = sorted(events, key=lambda e: e.t)
    work = np.zeros((9, 9))

    def apply(i: int) -> None:
        k, moments, m, C, xc, yc = plan[i]
        before = kinetic_energy(c, pos, vel, work)
        set_payload(c, moments, m_ch)
        jump = kinetic_energy(c, pos, vel, work) - before
        truths.append(PayloadTruth(order[i], k, k * sample_time, float(m), float(C), float(xc), float(yc), float(jump)))

    return split_at_events(step, [p[0] for p in plan], apply)


def split_at_events(step: Any, samples: list[int], apply: Any) -> Any:
    """``step(k0, k1)`` that calls ``apply(i)`` before the first sample ``samples[i]`` of event i (in
    time order; an event before k0 at the first call applies there) and ``step`` on the samples between."""
    done = [0]

    def stepped(k0: int, k1: int) -> None:
        a = k0
        while done[0] < len(samples) and samples[done[0]] < k1:
            k = max(samples[done[0]], a)
            if k > a:
                step(a, k)
                a = k
            apply(done[0])
            done[0] += 1
        if a < k1:
            step(a, k1)

    return stepped
