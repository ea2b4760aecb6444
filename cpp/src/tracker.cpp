// PayloadTracker (include/agvdyn_ff/tracker.hpp): the kernels of agvdyn/online/_kernels.py (track_rows,
// _update, _joseph, _add_row, _detect, _reset_payload, _inverse_spd), statement by statement and in the
// same order of floating-point operations, so that both give the same numbers (round-off; the
// shared vectors hold them to 1e-9 relative). Plain loops on fixed-size storage rather than Eigen
// expressions: the summation order must be Python's.
#include "agvdyn_ff/tracker.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace agvdyn::ff {
namespace {

constexpr int NS = kTrackerStates;
// CUSUM level below which its window (start sample and statistics) restarts (_kernels.RESTART).
constexpr double kRestart = 1.0;
// A row bias learnt from fewer than kYoungWarmups x warm_rows rows of its kind is young (_kernels.YOUNG_WARMUPS).
constexpr double kYoungWarmups = 10.0;

bool finite(double x) noexcept { return std::isfinite(x); }
bool positive(double x) noexcept { return std::isfinite(x) && x > 0; }

// I += f f^T w, b += f z w (_kernels._add_row)
void add_row(TrackerMatrix& I, TrackerVector& b, const double* f, double z, double w) noexcept {
  for (int p = 0; p < NS; ++p) {
    b[p] += f[p] * z * w;
    for (int q = 0; q < NS; ++q) I(p, q) += f[p] * f[q] * w;
  }
}

// P <- (I - K f^T) P (I - K f^T)^T + K r_eff K^T (_kernels._joseph)
void joseph(TrackerMatrix& P, const double* K, const double* f, double r_eff) noexcept {
  double tmp[NS][NS];
  for (int p = 0; p < NS; ++p) {
    for (int q = 0; q < NS; ++q) {
      double a = 0.0;
      for (int s = 0; s < NS; ++s) a += ((p == s ? 1.0 : 0.0) - K[p] * f[s]) * P(s, q);
      tmp[p][q] = a;
    }
  }
  for (int p = 0; p < NS; ++p) {
    for (int q = 0; q < NS; ++q) {
      double a = 0.0;
      for (int s = 0; s < NS; ++s) a += tmp[p][s] * ((q == s ? 1.0 : 0.0) - K[q] * f[s]);
      P(p, q) = a + K[p] * r_eff * K[q];
    }
  }
}

// out = A^-1 of a symmetric positive definite matrix by Gauss-Jordan without pivoting (_kernels._inverse_spd).
void inverse_spd(const double (&A)[NS][NS], double (&out)[NS][NS]) noexcept {
  double M[NS][NS];
  for (int p = 0; p < NS; ++p) {
    for (int q = 0; q < NS; ++q) {
      M[p][q] = A[p][q];
      out[p][q] = p == q ? 1.0 : 0.0;
    }
  }
  for (int c = 0; c < NS; ++c) {
    const double d = M[c][c];
    for (int q = 0; q < NS; ++q) {
      M[c][q] /= d;
      out[c][q] /= d;
    }
    for (int p = 0; p < NS; ++p) {
      if (p == c) continue;
      const double f = M[p][c];
      if (f != 0.0) {
        for (int q = 0; q < NS; ++q) {
          M[p][q] -= f * M[c][q];
          out[p][q] -= f * out[c][q];
        }
      }
    }
  }
}

// A payload change (_kernels._reset_payload): m_ch, C_ch and the young row biases the window saw (fewer
// than `young` rows of their kind) re-estimated together from a CUSUM's window (I, b), priors at their
// values with variances reset_var and bias_var, the other biases held; the covariance of the
// re-estimated states is the inverse of the normal matrix, decoupled from the rest.
void reset_payload(TrackerVector& theta, TrackerMatrix& P, const TrackerMatrix& I, const TrackerVector& b,
                   const Vector2& reset_var, const Eigen::Matrix<double, 9, 1>& n_rows, double young,
                   double bias_var) noexcept {
  bool sel[NS];
  sel[0] = true;
  sel[1] = true;
  for (int j = 2; j < NS; ++j) sel[j] = I(j, j) > 0.0 && n_rows[j - 2] < young;
  double A[NS][NS] = {};
  double r[NS] = {};
  for (int p = 0; p < NS; ++p) {
    if (!sel[p]) {
      A[p][p] = 1.0;
      continue;
    }
    const double prior = 1.0 / (p < 2 ? reset_var[p] : bias_var);
    r[p] = theta[p] * prior + b[p];
    for (int q = 0; q < NS; ++q) {
      if (sel[q]) {
        A[p][q] = I(p, q);
      } else {
        r[p] -= I(p, q) * theta[q];
      }
    }
    A[p][p] += prior;
  }
  double Ainv[NS][NS];
  inverse_spd(A, Ainv);
  double x[NS];
  for (int p = 0; p < NS; ++p) {
    double a = 0.0;
    for (int q = 0; q < NS; ++q) a += Ainv[p][q] * r[q];
    x[p] = a;
  }
  for (int p = 0; p < NS; ++p) {
    if (!sel[p]) continue;
    theta[p] = x[p];
    for (int q = 0; q < NS; ++q) {
      P(p, q) = 0.0;
      P(q, p) = 0.0;
    }
  }
  for (int p = 0; p < NS; ++p) {
    if (!sel[p]) continue;
    for (int q = 0; q < NS; ++q) {
      if (sel[q]) P(p, q) = Ainv[p][q];
    }
  }
}

}  // namespace

const char* label(RowKind kind) noexcept {
  static const char* names[7] = {"none", "x_ch+", "x_ch-", "y_ch+", "y_ch-", "gamma_ch+", "gamma_ch-"};
  const int k = static_cast<int>(kind);
  return (k >= 0 && k <= 6) ? names[k] : "?";
}

Status PayloadTracker::create(const Vector2& nominal, const Vector2& nominal_std, double dt,
                              const TrackerSettings& s, PayloadTracker* tracker) noexcept {
  if (tracker == nullptr) return Status::invalid_model;
  for (double v : {s.change_size, s.gate, s.correlation, s.rotation_correlation, s.threshold, s.random_walk,
                   s.bias_walk, s.reset_std, s.noise_time, s.initial_std, s.bias_std, s.noise, dt}) {
    if (!positive(v)) return Status::invalid_model;
  }
  if (s.warm_rows < 0 || !positive(nominal[0]) || !positive(nominal[1]) || !nominal_std.allFinite() ||
      nominal_std.minCoeff() < 0) {
    return Status::invalid_model;
  }
  PayloadTracker t;
  t.settings_ = s;
  t.nominal_ = nominal;
  t.dt_ = dt;
  // TrackerSettings.constants
  for (int i = 0; i < 2; ++i) {
    const double walk = s.random_walk * nominal[i], prior = s.reset_std * nominal[i];
    t.delta_[i] = s.change_size * nominal[i];
    t.q_[i] = (walk * walk) * dt;
    t.reset_var_[i] = prior * prior;
  }
  t.q_b_ = s.bias_walk * s.bias_walk;
  t.bias_var_ = s.bias_std * s.bias_std;
  // TrackerState.initial
  State& st = t.state_;
  st.theta.setZero();
  st.theta.head<2>() = nominal;
  st.P.setZero();
  for (int i = 0; i < 2; ++i) {
    const double sd = std::max(nominal_std[i], s.initial_std * std::abs(nominal[i]));
    st.P(i, i) = sd * sd;
  }
  for (int j = 2; j < NS; ++j) st.P(j, j) = s.bias_std * s.bias_std;
  st.R = Eigen::Vector3d::Constant(s.noise);
  *tracker = t;
  return Status::ok;
}

Vector2 PayloadTracker::std() const noexcept {
  return Vector2(std::sqrt(state_.P(0, 0)), std::sqrt(state_.P(1, 1)));
}

void PayloadTracker::begin_log() noexcept {
  state_.g.fill(0.0);
  state_.sample = 0;
}

Status PayloadTracker::set_state(const State& state) noexcept {
  bool ok = state.theta.allFinite() && state.P.allFinite() && state.R.allFinite() && state.n_rows.allFinite();
  for (int c = 0; c < 4; ++c) ok = ok && finite(state.g[c]) && state.Iw[c].allFinite() && state.bw[c].allFinite();
  if (!ok) return Status::non_finite_input;
  state_ = state;
  return Status::ok;
}

Status PayloadTracker::update(const TrackerRow& row, TrackerOutput& out) noexcept {
  State& st = state_;
  const std::int64_t n = st.sample++;
  out.event = 0;
  out.n_events = 0;
  const int c = static_cast<int>(row.kind);
  Status status = Status::ok;
  if (c < 0 || c > 6) {
    status = Status::unknown_row_kind;
  } else if (!finite(row.phi_m) || !finite(row.phi_C) || !finite(row.z)) {
    status = c == 0 ? Status::ok : Status::non_finite_input;
  }
  if (status != Status::ok || c == 0) {
    out.nis = std::numeric_limits<double>::quiet_NaN();
    out.estimate = st.theta.head<2>();
    out.std = std();
    return status;
  }
  // _kernels._update
  const double phi_m = row.phi_m, phi_c = row.phi_C, z = row.z;
  const int j = 1 + c;            // the bias state of this kind of row
  const int cls = (c - 1) / 2;    // its coordinate: noise class
  double f[NS] = {0, 0, 0, 0, 0, 0, 0, 0};
  f[0] = phi_m;
  f[1] = phi_c;
  f[j] = 1.0;
  const double r_c = st.R[cls];
  const double r_eff = r_c * (cls == 2 ? settings_.rotation_correlation : settings_.correlation);
  const double noise = std::sqrt(r_c);
  const bool excited[2] = {std::abs(phi_m) * delta_[0] >= settings_.gate * noise,
                           std::abs(phi_c) * delta_[1] >= settings_.gate * noise};
  for (int i = 0; i < 2; ++i) {  // random walk in the excited directions only, capped at the reset level
    if (excited[i]) st.P(i, i) = std::min(st.P(i, i) + q_[i], reset_var_[i]);
  }
  st.P(j, j) += q_b_ * dt_;
  double r = z;
  double Pf[NS];
  for (int p = 0; p < NS; ++p) {
    r -= f[p] * st.theta[p];
    double a = 0.0;
    for (int s = 0; s < NS; ++s) a += st.P(p, s) * f[s];
    Pf[p] = a;
  }
  double fPf = 0.0;
  for (int p = 0; p < NS; ++p) fPf += f[p] * Pf[p];
  out.nis = r * r / (fPf + r_c);
  const bool warm = st.n_rows[c - 1] >= static_cast<double>(settings_.warm_rows);
  const bool tested = warm && excited[cls == 2 ? 1 : 0];  // this row's own CUSUMs run on it
  double gmax = 0.0;
  for (int i = 0; i < 2; ++i) {
    for (int s = 0; s < 2; ++s) {
      const int w = 2 * i + s;
      if (warm && excited[i] && ((cls == 2) == (i == 1))) {  // m_ch from translation rows, C_ch from rotation
        const double sign = s == 0 ? 1.0 : -1.0;
        const double fi = i == 0 ? phi_m : phi_c;
        const double di = delta_[i] * fi;
        const double next = st.g[w] + (sign * delta_[i] * fi * r - 0.5 * (di * di)) / r_eff;
        if (st.g[w] <= kRestart && next > kRestart) {  // the window: rows since g last was <= kRestart
          st.start[w] = n;
          st.Iw[w].setZero();
          st.bw[w].setZero();
        }
        st.g[w] = std::max(next, 0.0);
        if (st.g[w] > kRestart) add_row(st.Iw[w], st.bw[w], f, z, 1.0 / r_eff);  // the rows its CUSUM ran on
      }
      gmax = std::max(gmax, st.g[w]);
    }
  }
  const double s_tot = fPf + r_eff;
  double K[NS];
  for (int p = 0; p < NS; ++p) K[p] = Pf[p] / s_tot;
  for (int i = 0; i < 2; ++i) {
    if (!excited[i]) K[i] = 0.0;  // directional update: nothing learnt along an unexcited parameter
  }
  joseph(st.P, K, f, r_eff);
  for (int p = 0; p < NS; ++p) st.theta[p] += K[p] * r;
  if (tested && gmax < 0.5 * settings_.threshold) {  // the noise: from rows the detector tests, frozen while a change builds up
    const double lam = std::max(1.0 / (st.n_rows[6 + cls] + 1.0), dt_ / settings_.noise_time);
    st.R[cls] += lam * (r * r - st.R[cls]);
  }
  st.n_rows[6 + cls] += 1.0;
  st.n_rows[c - 1] += 1.0;
  detect(out);
  out.estimate = st.theta.head<2>();
  out.std = std();
  return Status::ok;
}

// _kernels._detect: CUSUMs above the threshold are a payload change: m_ch and C_ch reset from the window
// of the highest of them, one event per parameter whose CUSUM fired; then every CUSUM restarts.
void PayloadTracker::detect(TrackerOutput& out) noexcept {
  State& st = state_;
  const std::int64_t n = st.sample - 1;
  int best = -1;
  for (int i = 0; i < 2; ++i) {
    const int s = st.g[2 * i] >= st.g[2 * i + 1] ? 0 : 1;
    const int w = 2 * i + s;
    if (st.g[w] <= settings_.threshold) continue;
    if (best < 0 || st.g[w] > st.g[best]) best = w;
    TrackerEvent& e = out.events[static_cast<std::size_t>(out.n_events++)];
    e.parameter = i;
    e.sign = s == 0 ? 1 : -1;
    e.sample = n;
    e.start = st.start[w];
    e.before = st.theta[i];
    e.before_var = st.P(i, i);
    ++event_count_;
    out.event |= 1 << i;
  }
  if (best < 0) return;
  reset_payload(st.theta, st.P, st.Iw[best], st.bw[best], reset_var_, st.n_rows,
                kYoungWarmups * static_cast<double>(settings_.warm_rows), bias_var_);
  for (int m = 0; m < out.n_events; ++m) {
    TrackerEvent& e = out.events[static_cast<std::size_t>(m)];
    e.after = st.theta[e.parameter];
    e.after_var = st.P(e.parameter, e.parameter);
  }
  st.g.fill(0.0);
  for (int w = 0; w < 4; ++w) {
    st.Iw[w].setZero();
    st.bw[w].setZero();
  }
}

}  // namespace agvdyn::ff
