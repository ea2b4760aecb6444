"""The optimisation problem: phase models, Fourier bases, row weights and the objectives with their gradients."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from agvdyn.determinacy import determinacy
from agvdyn.dynamics import feedforward_torques, projected_regressor
from agvdyn.kinematics import Mode, joint_motion, kinematic_model, nominal_steering
from agvdyn.platform import Geometry, Parameters
from agvdyn.trajectories.errors import TrajectoryError
from agvdyn.trajectories.experiments import identification_sequence
from agvdyn.trajectories.fourier import FourierSeries
from agvdyn.trajectories.limits import FloorSpace, Limits
from agvdyn.trajectories.segments import Trajectory, alignment
from agvdyn.trajectories.planner.settings import _OFFSETS, PHASES, PlanSettings
from agvdyn.trajectories.planner.weights import _log_cond, _row_weights, _softplus  # noqa: F401  (re-exported)


@dataclass(frozen=True, eq=False)
class _PhaseModel:
    """Constant facts of one phase: rows ``z^T P`` (z = (a, v, sign v, 1)), limits, feed-forward."""

    name: str
    mode: Mode
    coordinate: str
    alpha: np.ndarray       # (2,) steering angles at rest of the phase
    P: np.ndarray           # (4, 14): rows of eq. (19) per unit a, v, sign v and the offsets
    sigma: float
    knee: float             # acceleration at which the row's effective variance doubles (NoiseLevels)
    threshold: float
    guard: float            # the stiction guard the row weights assume, s (PlanSettings.guard)
    q_limit: float
    v_limit: float
    a_limit: float
    K: np.ndarray           # (3, 4): motor torque per unit a, v, sign v (eq. 21, nominal parameters)
    torque_limit: float


def _phase_models(geom: Geometry, params: Parameters, floor: FloorSpace, limits: Limits,
                  settings: PlanSettings) -> list[_PhaseModel]:
    half_length = (floor.length - geom.l) / 2
    if half_length <= 0:
        raise TrajectoryError(f"floor {floor.length:g} m x {floor.width:g} m: shorter than the vehicle "
                              f"(l = {geom.l:g} m): the straight motion needs l + 2 max|x_ch| <= the floor length")
    out = []
    for name, mode in PHASES:
        alpha = nominal_steering(geom, mode)
        alpha = np.zeros(2) if alpha is None else np.asarray(alpha, dtype=float)
        coordinate = "alpha_l" if name == "steer_left" else "alpha_r" if name == "steer_right" else mode.coordinates[0]
        col = 1 if name == "steer_right" else 0
        n = mode.dof
        s_dot = np.zeros((3, n))
        s_ddot = np.zeros((3, n))
        s_ddot[0, col] = 1.0
        s_dot[1, col], s_dot[2, col] = 1.0, 2.0
        al = np.tile(alpha, (3, 1))
        qd, qdd = joint_motion(geom, mode, al, s_dot, s_ddot)
        Y = projected_regressor(geom, mode, al, qd, qdd)[:, col, :10]
        u = feedforward_torques(geom, params, mode, al, s_dot, s_ddot)
        H = kinematic_model(geom, mode, al[:1])[0]
        P = np.zeros((4, 10 + _OFFSETS))
        P[0, :10] = Y[0]
        P[1, :10] = Y[2] - Y[1]
        P[2, :10] = 2 * Y[1] - Y[2]
        if settings.torque_offsets:
            P[3, 10:] = geom.i_G * H[5:, col]
        K = np.stack([u[0], u[2] - u[1], 2 * u[1] - u[2]])
        wheel = float(np.max(np.abs(H[5:, col])))
        if mode is Mode.PARKING:
            q_lim, v_lim, a_lim = settings.steering_excursion, limits.steering_rate, limits.steering_acceleration
        elif mode is Mode.ROTATION:
            q_lim, v_lim, a_lim = settings.max_heading, limits.yaw_rate, limits.yaw_acceleration
        else:
            q_lim, v_lim = half_length, min(limits.speed, settings.max_speed)
            a_lim = min(limits.acceleration, settings.max_acceleration)
        if wheel > 0:
            v_lim = min(v_lim, limits.wheel_speed / wheel)
        out.append(_PhaseModel(name, mode, coordinate, alpha, P, settings.weights_noise.of(coordinate),
                               settings.weights_noise.knee(coordinate), settings.threshold(coordinate),
                               settings.guard(coordinate, weights=True), q_lim, v_lim, a_lim, K,
                               limits.motor_torque * limits.feedforward_share))
    return out


def _alignments(geom: Geometry, settings: PlanSettings, dt: float) -> list:
    zero = np.zeros(2)
    rot = nominal_steering(geom, Mode.ROTATION)
    kw = dict(pause=settings.pause, rate=settings.align_rate, acceleration=settings.align_acceleration, dt=dt)
    return [alignment(zero, zero, **kw), alignment(zero, zero, **kw), alignment(zero, zero, **kw),
            alignment(zero, rot, **kw), alignment(rot, zero, **kw)]


def _sequence(geom: Geometry, series: dict[str, FourierSeries], settings: PlanSettings, dt: float,
              steering_periods: int = 1, name: str = "plan") -> Trajectory:
    traj = identification_sequence(geom, steer_left=series["steer_left"], steer_right=series["steer_right"],
                                   straight=series["straight"], rotation=series["rotation"],
                                   steering_periods=steering_periods, pause=settings.pause, dt=dt,
                                   align_rate=settings.align_rate, align_acceleration=settings.align_acceleration)
    return replace(traj, name=name)


# --- information of a phase from its Fourier coefficients -------------------------------------------

@dataclass(frozen=True, eq=False)
class _Basis:
    """Fourier basis of a phase on a fixed grid ``u = t / T`` in [0, 1): velocity, acceleration
    times T, position over T; and the projector onto series that start and end at rest. With
    ``periods`` p the harmonics are p, 2p, ..., H p: p repetitions of one period of H harmonics."""

    H: int
    n: int
    periods: int
    Cv: np.ndarray
    Ca: np.ndarray
    Cq: np.ndarray
    Pi: np.ndarray

    @classmethod
    def of(cls, H: int, n: int, periods: int = 1) -> "_Basis":
        u = (np.arange(n) + 0.5) / n
        k = periods * np.arange(1, H + 1, dtype=float)
        ph = 2 * np.pi * np.outer(u, k)
        s, c = np.sin(ph), np.cos(ph)
        w = 2 * np.pi * k
        Cv = np.concatenate([c, s], axis=1)
        Ca = np.concatenate([-s * w, c * w], axis=1)
        Cq = np.concatenate([s / w, (1 - c) / w], axis=1)
        # at rest at both ends: sum a_k = 0, sum k b_k = 0 (orthogonal projector)
        N = np.zeros((2 * H, 2))
        N[:H, 0] = 1.0
        N[H:, 1] = k
        Q, _ = np.linalg.qr(N)
        Pi = np.eye(2 * H) - Q @ Q.T
        return cls(H, n, periods, Cv, Ca, Cq, Pi)


class _Problem:
    """The objective and its gradient for one start (fixed harmonics per phase)."""

    def __init__(self, models: list[_PhaseModel], harmonics: list[int], available: float, settings: PlanSettings,
                 params: np.ndarray, F0: np.ndarray, U0: np.ndarray, reference_log_std: np.ndarray | None,
                 sample_time: float, grid_points: list[int], O0: np.ndarray | None = None,
                 periods: list[int] | None = None):
        self.models = models
        periods = [1] * len(harmonics) if periods is None else list(periods)
        self.bases = [_Basis.of(H, n, p) for H, n, p in zip(harmonics, grid_points, periods)]
        self.available = available
        self.settings = settings
        self.log_p = np.log(np.abs(params[:10]))
        self.F0, self.U0 = F0, U0
        self.O0 = F0 if O0 is None else O0
        self.ref = reference_log_std
        self.Ts = sample_time
        self.t_min = np.array([max(settings.min_phase, 2 * math.pi * H * p / settings.max_frequency)
                               for H, p in zip(harmonics, periods)])
        if self.t_min.sum() >= available:
            raise TrajectoryError(f"{available:.1f} s for the four phases: too short for phases of at least "
                                  f"{', '.join(f'{x:.1f}' for x in self.t_min)} s; expected a longer --duration")
        self.sizes = [2 * H for H in harmonics]
        self.offsets = np.concatenate([[0], np.cumsum(self.sizes)])

    # variables: coefficients of the four phases, then four duration logits
    def split(self, x: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
        thetas = [x[a:b] for a, b in zip(self.offsets[:-1], self.offsets[1:])]
        return thetas, x[self.offsets[-1]:]

    def durations(self, eta: np.ndarray) -> np.ndarray:
        e = np.exp(eta - eta.max())
        return self.t_min + (self.available - self.t_min.sum()) * e / e.sum()

    def scale(self, j: int, c: np.ndarray, T: float) -> tuple[float, int, int, float]:
        """Largest scale of the series c within the limits of phase j: (scale, limit index, sample, peak)."""
        m, B = self.models[j], self.bases[j]
        v0, a0, q0 = B.Cv @ c, B.Ca @ c / T, T * (B.Cq @ c)
        cands = []
        for k, (x, lim) in enumerate(((v0, m.v_limit), (a0, m.a_limit), (q0, m.q_limit))):
            i = int(np.argmax(np.abs(x)))
            cands.append((lim / max(abs(x[i]), 1e-12), k, i, x[i]))
        y = np.outer(a0, m.K[0]) + np.outer(v0, m.K[1])
        room = m.torque_limit - np.abs(np.outer(np.sign(v0), m.K[2]))
        ratio = np.where(np.abs(y) > 1e-12, np.maximum(room, 1e-9) / np.maximum(np.abs(y), 1e-12), np.inf)
        flat = int(np.argmin(ratio))
        cands.append((float(ratio.flat[flat]), 3, flat, float(y.flat[flat])))
        best = min(cands, key=lambda c_: c_[0])
        return best[0] * self.settings.margin, best[1], best[2], best[3]

    def smooth_scale(self, j: int, c: np.ndarray, T: float) -> tuple[float, np.ndarray]:
        """The optimiser's scale of the series c in phase j and its gradient in c: ``margin / L`` with
        ``L`` the ``peak_exponent``-norm over the samples and limits of ``|x| / limit`` (velocity,
        acceleration, excursion, motor torque), a smooth upper bound of the largest (exact: inf).
        The exact max has kinks where two peaks are equal, at which L-BFGS-B stalls."""
        m, B = self.models[j], self.bases[j]
        p = self.settings.peak_exponent
        if math.isinf(p):
            s, kind, i, peak = self.scale(j, c, T)
            row = (B.Cv[i] if kind == 0 else B.Ca[i] / T if kind == 1 else T * B.Cq[i] if kind == 2
                   else m.K[0, i % 4] * B.Ca[i // 4] / T + m.K[1, i % 4] * B.Cv[i // 4])  # the peak's row only
            return s, -s / peak * row
        v0, a0, q0 = B.Cv @ c, B.Ca @ c / T, T * (B.Cq @ c)
        y = np.outer(a0, m.K[0]) + np.outer(v0, m.K[1])
        room = np.maximum(m.torque_limit - np.abs(np.outer(np.sign(v0), m.K[2])), 1e-9)
        parts = (np.abs(v0) / m.v_limit, np.abs(a0) / m.a_limit, np.abs(q0) / m.q_limit, np.abs(y) / room)
        top = max(float(u.max()) for u in parts)
        if top <= 0:
            return 0.0, np.zeros_like(c)
        ratios = [(u / top) ** (p - 1) for u in parts]
        L = top * sum(float(np.sum(r * u / top)) for r, u in zip(ratios, parts)) ** (1 / p)
        w = [r * (top / L) ** (p - 1) for r in ratios]  # dL/du
        dL = (B.Cv.T @ (w[0] * np.sign(v0)) / m.v_limit + B.Ca.T @ (w[1] * np.sign(a0)) / (T * m.a_limit)
              + T * (B.Cq.T @ (w[2] * np.sign(q0))) / m.q_limit)
        wy = w[3] * np.sign(y) / room
        dL += B.Ca.T @ (wy @ m.K[0]) / T + B.Cv.T @ (wy @ m.K[1])
        s = self.settings.margin / L
        return s, -s / L * dL

    def phase_moments(self, j: int, theta: np.ndarray, T: float, want_grad: bool = False):
        """Moment matrices (4, 4) of phase j in units of T_s rows: of the rows kept (validity weights;
        for F and U) and of the rows times their variance factor (for Omega), its penalty time (s;
        see :func:`_row_weights`), and what the gradient needs."""
        m, B = self.models[j], self.bases[j]
        c = B.Pi @ theta
        s, ds_dc = self.smooth_scale(j, c, T)
        v0, a0 = B.Cv @ c, B.Ca @ c / T
        v, a = s * v0, s * a0
        wts = _row_weights(v, a, m.threshold, m.knee, self.settings, self.settings.weights_noise.saturation, m.guard)
        Z = np.stack([a, v, np.sign(v), np.ones_like(v)], axis=1)
        unit = T / B.n / self.Ts
        M = unit * (Z * wts.wU[:, None]).T @ Z
        MO = unit * (Z * wts.wO[:, None]).T @ Z
        penalty = T / B.n * float(np.sum(wts.pen))
        if not want_grad:
            return M, MO, penalty, None
        return M, MO, penalty, (c, s, ds_dc, v0, a0, Z, wts, unit, T / B.n)

    def information(self, x: np.ndarray, want_grad: bool = False):
        thetas, eta = self.split(x)
        T = self.durations(eta)
        F, O, U = self.F0.copy(), self.O0.copy(), self.U0.copy()
        cache, band = [], 0.0
        for j, m in enumerate(self.models):
            M, MO, b, aux = self.phase_moments(j, thetas[j], T[j], want_grad)  # b: penalty time
            F += m.P.T @ M @ m.P / m.sigma**2
            O += m.P.T @ MO @ m.P / m.sigma**2
            U += m.P[:, :10].T @ M @ m.P[:, :10]
            band += b
            cache.append(aux)
        return F, O, U, T, cache, band / self.available

    def objective(self, x: np.ndarray) -> float:
        F, O, U, _, _, band = self.information(x)
        return self.criterion(F, O, U)[0] + band

    def criterion(self, F: np.ndarray, O: np.ndarray, U: np.ndarray
                  ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """Objective J(F, Omega, U) and its derivatives dJ/dF, dJ/dOmega (14, 14), dJ/dU (10, 10).

        The covariance is the sandwich ``Cov = F^-1 Omega F^-1`` (one weight per coordinate, rows
        whose variance grows with the acceleration); for a J of it with ``H = dJ/dCov``:
        ``dJ/dF = -(F^-1 H Cov + Cov H F^-1)``, ``dJ/dOmega = F^-1 H F^-1``."""
        st = self.settings
        dF, dO, dU = np.zeros_like(F), np.zeros_like(O), np.zeros_like(U)
        if determinacy(F).undetermined.any():  # no inverse of a singular F: the worst objective
            return 1e6, dF, dO, dU
        Fi = np.linalg.inv(F)
        Cov = Fi @ O @ Fi
        Cov = 0.5 * (Cov + Cov.T)
        if st.objective == "d-optimal":
            sign, logdet = np.linalg.slogdet(Cov[:10, :10])
            if sign <= 0:
                return 1e6, dF, dO, dU
            H = np.zeros_like(F)
            H[:10, :10] = np.linalg.inv(Cov[:10, :10]) / 10
            dF = -(Fi @ H @ Cov + Cov @ H @ Fi)
            dO = Fi @ H @ Fi
            return float(logdet) / 10, 0.5 * (dF + dF.T), 0.5 * (dO + dO.T), dU
        log_cond, dlc = _log_cond(U)
        if st.objective == "cond":
            return log_cond, dF, dO, dlc
        var = np.diag(Cov)[:10]
        if np.any(var <= 0):
            return 1e6, dF, dO, dU
        log_rel = 0.5 * np.log(var) - self.log_p
        J = float(np.mean(log_rel))
        g = np.full(10, 0.1)  # dJ/dlog_rel
        if self.ref is not None and st.reference_penalty > 0:
            excess = log_rel - self.ref - np.log(st.margins())
            sp, dsp = _softplus(excess, 0.05)
            J += st.reference_penalty * float(np.sum(sp ** 2))
            g += st.reference_penalty * 2 * sp * dsp
        sp, dsp = _softplus(np.array([log_cond - math.log(st.cond_target)]), 0.05)
        J += st.reference_penalty * float(sp[0] ** 2)
        dU = st.reference_penalty * 2 * sp[0] * dsp[0] * dlc
        # d log_rel_i = 0.5 dvar_i / var_i
        h = np.zeros(F.shape[0])
        h[:10] = g * 0.5 / var
        FH = Fi * h  # F^-1 H with H = diag(h)
        dF = -(FH @ Cov + (FH @ Cov).T)
        dO = FH @ Fi
        return J, dF, 0.5 * (dO + dO.T), dU

    def __call__(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        F, O, U, T, cache, band = self.information(x, want_grad=True)
        J, dF, dO, dU = self.criterion(F, O, U)
        if J >= 1e6:
            return J, np.zeros_like(x)
        lam = 1.0 / self.available
        J += band
        thetas, eta = self.split(x)
        grad = np.zeros_like(x)
        GF, GO = [], []  # dJ/dM (through F and U) and dJ/dMO per phase
        for j, (m, aux) in enumerate(zip(self.models, cache)):
            Gf = m.P @ dF @ m.P.T / m.sigma**2 + m.P[:, :10] @ dU @ m.P[:, :10].T
            Go = m.P @ dO @ m.P.T / m.sigma**2
            GF.append(0.5 * (Gf + Gf.T))
            GO.append(0.5 * (Go + Go.T))
            grad[self.offsets[j]:self.offsets[j + 1]] = self._theta_gradient(j, GF[j], GO[j], lam, aux, T[j])
        # durations: finite differences per phase (the basis lives on t / T, so only scalars change)
        dJ_dT = np.zeros(4)
        for j, m in enumerate(self.models):
            h = 1e-4 * T[j]
            Mp, MOp, bp, _ = self.phase_moments(j, thetas[j], T[j] + h)
            Mm, MOm, bm, _ = self.phase_moments(j, thetas[j], T[j] - h)
            dJ_dT[j] = float(np.sum(GF[j] * (Mp - Mm)) + np.sum(GO[j] * (MOp - MOm)) + lam * (bp - bm)) / (2 * h)
        e = np.exp(eta - eta.max())
        sm = e / e.sum()
        R = self.available - self.t_min.sum()
        dT_deta = R * (np.diag(sm) - np.outer(sm, sm))
        grad[self.offsets[-1]:] = dT_deta.T @ dJ_dT
        return J, grad

    def _theta_gradient(self, j: int, GF: np.ndarray, GO: np.ndarray, lam: float, aux, T: float) -> np.ndarray:
        B = self.bases[j]
        c, s, ds_dc, v0, a0, Z, w, unit, dt_row = aux
        ZF, ZO = Z @ GF, Z @ GO  # (n, 4)
        qF, qO = np.einsum("ni,ni->n", ZF, Z), np.einsum("ni,ni->n", ZO, Z)
        g_a = unit * (2 * w.wU * ZF[:, 0] + 2 * w.wO * ZO[:, 0] + w.wU_a * qF + w.wO_a * qO) + lam * dt_row * w.pen_a
        g_v = unit * (2 * w.wU * ZF[:, 1] + 2 * w.wO * ZO[:, 1] + w.wU_v * qF + w.wO_v * qO) + lam * dt_row * w.pen_v
        # v = s Cv c, a = s Ca c / T, and s(c) (smooth_scale)
        dc = s * (B.Cv.T @ g_v + B.Ca.T @ g_a / T)
        dJ_ds = float(g_v @ v0 + g_a @ a0)
        dc += dJ_ds * ds_dc
        return B.Pi @ dc
