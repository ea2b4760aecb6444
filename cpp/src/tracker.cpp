// PayloadTracker (include/agvdyn_ff/tracker.hpp): the kernels of agvdyn/online/_kernels.py (track_rows,
// _update, _joseph, _add_row, _detect, _reset_payload, _inverse_spd, offset_estimate), statement by
// statement and in the same order of floating-point operations, so that both give the same numbers
// (round-off; the shared vectors hold them to 1e-9 relative). Plain loops on fixed-size storage rather
// than Eigen expressions: the summation order must be Python's. The loops run over N states, a
// template parameter (8, or 9 with com_offset) as in Python's compiled kernels (a literal there).
#include "agvdyn_ff/tracker.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace agvdyn::ff {
namespace {

constexpr int NS = kTrackerStates;
constexpr int OFFSET = kOffsetState;
// CUSUM level below which its window (start sample and statistics) restarts (_kernels.RESTART).
constexpr double kRestart = 1.0;
// A row bias learnt from fewer than kYoungWarmups x warm_rows rows of its kinds is young (_kernels.YOUNG_WARMUPS).
constexpr int kCarLike = 3;  // noise class of the car-like x_ch rows (_kernels.CAR_LIKE)
constexpr int kTested = kRowKinds + kNoiseClasses;  // n_rows: tested rows per kind from here (_kernels.TESTED)

// The bias state and noise class of row kind c (1..8), as _kernels._update: the car-like x_ch rows (7, 8) have
// the straight ones' biases and a noise class of their own.
int bias_of_kind(int c) noexcept { return c <= 6 ? 1 + c : c - 5; }
int class_of_kind(int c) noexcept { return c <= 6 ? (c - 1) / 2 : kCarLike; }
constexpr double kYoungWarmups = 10.0;
// y_c's variance counts as informed below this fraction of its prior (_kernels.INFORMED).
constexpr double kInformed = 1.0 - 1e-6;

bool finite(double x) noexcept { return std::isfinite(x); }
bool positive(double x) noexcept { return std::isfinite(x) && x > 0; }

template <int N>
using MatrixN = typename TrackerStateOf<N>::Matrix;
template <int N>
using VectorN = typename TrackerStateOf<N>::Vector;

// I += f f^T w, b += f z w (_kernels._add_row)
template <int N>
void add_row(MatrixN<N>& I, VectorN<N>& b, const double* f, double z, double w) noexcept {
  for (int p = 0; p < N; ++p) {
    b[p] += f[p] * z * w;
    for (int q = 0; q < N; ++q) I(p, q) += f[p] * f[q] * w;
  }
}

// P <- (I - K f^T) P (I - K f^T)^T + K r_eff K^T (_kernels._joseph)
template <int N>
void joseph(MatrixN<N>& P, const double* K, const double* f, double r_eff) noexcept {
  double tmp[N][N];
  for (int p = 0; p < N; ++p) {
    for (int q = 0; q < N; ++q) {
      double a = 0.0;
      for (int s = 0; s < N; ++s) a += ((p == s ? 1.0 : 0.0) - K[p] * f[s]) * P(s, q);
      tmp[p][q] = a;
    }
  }
  for (int p = 0; p < N; ++p) {
    for (int q = 0; q < N; ++q) {
      double a = 0.0;
      for (int s = 0; s < N; ++s) a += tmp[p][s] * ((q == s ? 1.0 : 0.0) - K[q] * f[s]);
      P(p, q) = a + K[p] * r_eff * K[q];
    }
  }
}

// bias j treated as unknown: variance var, uncorrelated, value kept (_kernels._unknown_bias)
template <int N>
void unknown_bias(MatrixN<N>& P, int j, double var) noexcept {
  for (int q = 0; q < N; ++q) {
    P(j, q) = 0.0;
    P(q, j) = 0.0;
  }
  P(j, j) = var;
}

// _kernels._twin_bias: at the first row of kind c (1..6) whose twin (same coordinate, other sign) is warm, its
// bias starts at the twin's with the twin's variance + twin_var; true when the kind counts as warm through its twin.
template <int N>
bool twin_bias(VectorN<N>& theta, MatrixN<N>& P, const Eigen::Matrix<double, kTrackerCounts, 1>& n_rows, int c, int j,
               double warm, double twin_var) noexcept {
  if (c > 6) return false;
  const int twin = c % 2 == 1 ? c + 1 : c - 1;
  if (n_rows[twin - 1] < warm) return false;
  if (n_rows[c - 1] == 0.0 && (c > 2 || n_rows[c + 5] == 0.0)) {  // the bias's first row (x_ch: car-like ones too)
    const double var = P(1 + twin, 1 + twin) + twin_var;
    theta[j] = theta[1 + twin];
    unknown_bias<N>(P, j, var);
  }
  return true;
}

// out = A^-1 of a symmetric positive definite matrix by Gauss-Jordan without pivoting (_kernels._inverse_spd).
template <int N>
void inverse_spd(const double (&A)[N][N], double (&out)[N][N]) noexcept {
  double M[N][N];
  for (int p = 0; p < N; ++p) {
    for (int q = 0; q < N; ++q) {
      M[p][q] = A[p][q];
      out[p][q] = p == q ? 1.0 : 0.0;
    }
  }
  for (int c = 0; c < N; ++c) {
    const double d = M[c][c];
    for (int q = 0; q < N; ++q) {
      M[c][q] /= d;
      out[c][q] /= d;
    }
    for (int p = 0; p < N; ++p) {
      if (p == c) continue;
      const double f = M[p][c];
      if (f != 0.0) {
        for (int q = 0; q < N; ++q) {
          M[p][q] -= f * M[c][q];
          out[p][q] -= f * out[c][q];
        }
      }
    }
  }
}

// A payload change (_kernels._reset_payload): m_ch, C_ch (and m_ch y_c with N = 9) and the young row biases
// the window saw (fewer than `young` rows of their kind) re-estimated together from a CUSUM's window (I, b),
// priors at their values with variances reset_var and bias_var, the other biases held; the covariance of
// the re-estimated states is the inverse of the normal matrix, decoupled from the rest.
template <int N>
void reset_payload(VectorN<N>& theta, MatrixN<N>& P, const MatrixN<N>& I, const VectorN<N>& b,
                   const Eigen::Vector3d& reset_var, const Eigen::Matrix<double, kTrackerCounts, 1>& n_rows,
                   double young,
                   double bias_var) noexcept {
  bool sel[N];
  sel[0] = true;
  sel[1] = true;
  for (int j = 2; j < NS; ++j) {
    const double seen = n_rows[j - 2] + (j < 4 ? n_rows[j + 4] : 0.0);  // x_ch biases: straight and car-like rows
    sel[j] = I(j, j) > 0.0 && seen < young;
    const double tested = n_rows[kTested + j - 2] + (j < 4 ? n_rows[kTested + j + 4] : 0.0);
    if (!sel[j] && seen > 0.0 && tested < young / kYoungWarmups) {
      unknown_bias<N>(P, j, bias_var);  // learnt from rows no CUSUM checked: it may hold the change
    }
  }
  if constexpr (N > NS) sel[OFFSET] = true;
  double A[N][N] = {};
  double r[N] = {};
  for (int p = 0; p < N; ++p) {
    if (!sel[p]) {
      A[p][p] = 1.0;
      continue;
    }
    const double prior = 1.0 / (p < 2 ? reset_var[p] : (p == OFFSET ? reset_var[2] : bias_var));
    r[p] = theta[p] * prior + b[p];
    for (int q = 0; q < N; ++q) {
      if (sel[q]) {
        A[p][q] = I(p, q);
      } else {
        r[p] -= I(p, q) * theta[q];
      }
    }
    A[p][p] += prior;
  }
  double Ainv[N][N];
  inverse_spd<N>(A, Ainv);
  double x[N];
  for (int p = 0; p < N; ++p) {
    double a = 0.0;
    for (int q = 0; q < N; ++q) a += Ainv[p][q] * r[q];
    x[p] = a;
  }
  for (int p = 0; p < N; ++p) {
    if (!sel[p]) continue;
    theta[p] = x[p];
    for (int q = 0; q < N; ++q) {
      P(p, q) = 0.0;
      P(q, p) = 0.0;
    }
  }
  for (int p = 0; p < N; ++p) {
    if (!sel[p]) continue;
    for (int q = 0; q < N; ++q) {
      if (sel[q]) P(p, q) = Ainv[p][q];
    }
  }
}

}  // namespace

const char* label(RowKind kind) noexcept {
  static const char* names[kRowKinds + 1] = {"none",      "x_ch+",     "x_ch-",          "y_ch+",         "y_ch-",
                                             "gamma_ch+", "gamma_ch-", "x_ch+ car-like", "x_ch- car-like"};
  const int k = static_cast<int>(kind);
  return (k >= 0 && k <= kRowKinds) ? names[k] : "?";
}

Status PayloadTracker::create(const Vector2& nominal, const Vector2& nominal_std, double dt,
                              const TrackerSettings& s, PayloadTracker* tracker) noexcept {
  return create(nominal, nominal_std, 0.0, std::numeric_limits<double>::infinity(), dt, s, tracker);
}

Status PayloadTracker::create(const Vector2& nominal, const Vector2& nominal_std, double y_c, double y_c_std,
                              double dt, const TrackerSettings& s, PayloadTracker* tracker) noexcept {
  if (tracker == nullptr) return Status::invalid_model;
  for (double v : {s.change_size, s.gate, s.correlation, s.rotation_correlation, s.threshold, s.random_walk,
                   s.bias_walk, s.reset_std, s.noise_time, s.initial_std, s.bias_std, s.twin_bias_std, s.noise,
                   s.offset_change,
                   s.offset_std, s.offset_walk, dt}) {
    if (!positive(v)) return Status::invalid_model;
  }
  if (s.warm_rows < 0 || !positive(nominal[0]) || !positive(nominal[1]) || !nominal_std.allFinite() ||
      nominal_std.minCoeff() < 0 || !finite(y_c) || y_c_std < 0) {
    return Status::invalid_model;
  }
  PayloadTracker t;
  t.settings_ = s;
  t.state_ = State{};
  t.offset_state_ = OffsetState{};
  t.nominal_ = nominal;
  t.dt_ = dt;
  // TrackerSettings.constants
  for (int i = 0; i < 2; ++i) {
    const double walk = s.random_walk * nominal[i], prior = s.reset_std * nominal[i];
    t.delta_[i] = s.change_size * nominal[i];
    t.q_[i] = (walk * walk) * dt;
    t.reset_var_[i] = prior * prior;
  }
  const double walk_y = s.offset_walk * nominal[0], prior_y = s.offset_std * nominal[0];
  t.delta_[2] = s.offset_change * nominal[0];
  t.q_[2] = (walk_y * walk_y) * dt;
  t.reset_var_[2] = prior_y * prior_y;
  t.q_b_ = s.bias_walk * s.bias_walk;
  t.bias_var_ = s.bias_std * s.bias_std;
  t.twin_var_ = s.twin_bias_std * s.twin_bias_std;
  // TrackerState.initial
  if (s.com_offset) {
    t.initial_state(t.offset_state_, nominal, nominal_std);
    OffsetState& st = t.offset_state_;
    const double sd = std::isfinite(y_c_std) ? std::max(y_c_std, s.offset_change) : s.offset_std;
    const double spread = nominal[0] * sd;
    st.theta[OFFSET] = nominal[0] * y_c;
    st.P(OFFSET, OFFSET) = spread * spread + (y_c * y_c) * st.P(0, 0);
    st.P(0, OFFSET) = st.P(OFFSET, 0) = y_c * st.P(0, 0);
  } else {
    t.initial_state(t.state_, nominal, nominal_std);
  }
  *tracker = t;
  return Status::ok;
}

// TrackerState.initial: m_ch, C_ch with std at least initial_std x value, biases 0 with bias_std, R = noise
template <int N>
void PayloadTracker::initial_state(TrackerStateOf<N>& st, const Vector2& nominal, const Vector2& nominal_std) const noexcept {
  const TrackerSettings& s = settings_;
  st.theta.template head<2>() = nominal;
  for (int i = 0; i < 2; ++i) {
    const double sd = std::max(nominal_std[i], s.initial_std * std::abs(nominal[i]));
    st.P(i, i) = sd * sd;
  }
  for (int j = 2; j < NS; ++j) st.P(j, j) = s.bias_std * s.bias_std;
  st.R = Eigen::Vector4d::Constant(s.noise);
  for (int w = 0; w < 4; ++w) {
    st.Iw[w].setZero();
    st.bw[w].setZero();
  }
}

Vector2 PayloadTracker::std() const noexcept {
  if (settings_.com_offset) return Vector2(std::sqrt(offset_state_.P(0, 0)), std::sqrt(offset_state_.P(1, 1)));
  return Vector2(std::sqrt(state_.P(0, 0)), std::sqrt(state_.P(1, 1)));
}

void PayloadTracker::begin_log() noexcept {
  state_.g.fill(0.0);
  state_.sample = 0;
  offset_state_.g.fill(0.0);
  offset_state_.sample = 0;
}

namespace {
template <int N>
bool finite_state(const TrackerStateOf<N>& state) noexcept {
  bool ok = state.theta.allFinite() && state.P.allFinite() && state.R.allFinite() && state.n_rows.allFinite();
  for (int c = 0; c < 4; ++c) ok = ok && finite(state.g[c]) && state.Iw[c].allFinite() && state.bw[c].allFinite();
  return ok;
}
}  // namespace

Status PayloadTracker::set_state(const State& state) noexcept {
  if (settings_.com_offset) return Status::invalid_model;
  if (!finite_state(state)) return Status::non_finite_input;
  state_ = state;
  return Status::ok;
}

Status PayloadTracker::set_state(const OffsetState& state) noexcept {
  if (!settings_.com_offset) return Status::invalid_model;
  if (!finite_state(state)) return Status::non_finite_input;
  offset_state_ = state;
  return Status::ok;
}

// _kernels.offset_estimate: y_c = s / m with the delta-method std, inf while var(s) is at its prior.
void PayloadTracker::report(TrackerOutput& out) const noexcept {
  out.estimate = estimate();
  out.std = std();
  if (!settings_.com_offset) return;
  const OffsetState& st = offset_state_;
  const double m = st.theta[0], s = st.theta[OFFSET];
  out.y_c = s / m;
  if (!(st.P(OFFSET, OFFSET) < kInformed * reset_var_[2])) {
    out.y_c_std = std::numeric_limits<double>::infinity();
    return;
  }
  const double g0 = -s / (m * m);
  const double g1 = 1.0 / m;
  const double var = g0 * g0 * st.P(0, 0) + 2.0 * g0 * g1 * st.P(0, OFFSET) + g1 * g1 * st.P(OFFSET, OFFSET);
  out.y_c_std = std::sqrt(std::max(var, 0.0));
}

Status PayloadTracker::update(const TrackerRow& row, TrackerOutput& out) noexcept {
  ++(settings_.com_offset ? offset_state_.sample : state_.sample);
  out.event = 0;
  out.n_events = 0;
  const int c = static_cast<int>(row.kind);
  Status status = Status::ok;
  if (c < 0 || c > kRowKinds) {
    status = Status::unknown_row_kind;
  } else if (!finite(row.phi_m) || !finite(row.phi_C) || !finite(row.z) ||
             (settings_.com_offset && !finite(row.phi_y))) {
    status = c == 0 ? Status::ok : Status::non_finite_input;
  }
  if (status != Status::ok || c == 0) {
    out.nis = std::numeric_limits<double>::quiet_NaN();
    report(out);
    return status;
  }
  if (settings_.com_offset) {
    update_states<kOffsetStates>(row, out);
  } else {
    update_states<kTrackerStates>(row, out);
  }
  report(out);
  return Status::ok;
}

// _kernels._update with N states (the sample already counted)
template <int N>
void PayloadTracker::update_states(const TrackerRow& row, TrackerOutput& out) noexcept {
  TrackerStateOf<N>& st = state_of<N>();
  const std::int64_t n = st.sample - 1;
  const int c = static_cast<int>(row.kind);
  const double phi_m = row.phi_m, phi_c = row.phi_C, z = row.z;
  const int j = bias_of_kind(c);      // the bias state of this kind of row (car-like: the x_ch one)
  const int cls = class_of_kind(c);   // its noise class
  double f[N] = {};
  f[0] = phi_m;
  f[1] = phi_c;
  f[j] = 1.0;
  const bool twin_warm =
      twin_bias<N>(st.theta, st.P, st.n_rows, c, j, static_cast<double>(settings_.warm_rows), twin_var_);
  const double r_c = st.R[cls];
  const double r_eff = r_c * (cls == 2 ? settings_.rotation_correlation : settings_.correlation);
  const double noise = std::sqrt(r_c);
  const bool excited[2] = {std::abs(phi_m) * delta_[0] >= settings_.gate * noise,
                           std::abs(phi_c) * delta_[1] >= settings_.gate * noise};
  for (int i = 0; i < 2; ++i) {  // random walk in the excited directions only, capped at the reset level
    if (excited[i]) st.P(i, i) = std::min(st.P(i, i) + q_[i], reset_var_[i]);
  }
  bool excited_y = false;
  if constexpr (N > NS) {  // m_ch y_c: the same gating and random walk (its column is nonzero in car-like rows only)
    f[OFFSET] = row.phi_y;
    excited_y = std::abs(row.phi_y) * delta_[2] >= settings_.gate * noise;
    if (excited_y) st.P(OFFSET, OFFSET) = std::min(st.P(OFFSET, OFFSET) + q_[2], reset_var_[2]);
  }
  st.P(j, j) += q_b_ * dt_;
  double r = z;
  double Pf[N];
  for (int p = 0; p < N; ++p) {
    r -= f[p] * st.theta[p];
    double a = 0.0;
    for (int s = 0; s < N; ++s) a += st.P(p, s) * f[s];
    Pf[p] = a;
  }
  double fPf = 0.0;
  for (int p = 0; p < N; ++p) fPf += f[p] * Pf[p];
  out.nis = r * r / (fPf + r_c);
  const bool warm = st.n_rows[c - 1] >= static_cast<double>(settings_.warm_rows) || twin_warm;
  // the noise class learns from the rows of its own test (car-like rows: also the C_ch-excited ones)
  const bool tested = warm && (excited[cls == 2 ? 1 : 0] || (cls == kCarLike && excited[1]));
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
        if (st.g[w] > kRestart) add_row<N>(st.Iw[w], st.bw[w], f, z, 1.0 / r_eff);  // the rows its CUSUM ran on
      }
      gmax = std::max(gmax, st.g[w]);
    }
  }
  const double s_tot = fPf + r_eff;
  double K[N];
  for (int p = 0; p < N; ++p) K[p] = Pf[p] / s_tot;
  for (int i = 0; i < 2; ++i) {
    if (!excited[i]) K[i] = 0.0;  // directional update: nothing learnt along an unexcited parameter
  }
  if constexpr (N > NS) {
    if (!excited_y) K[OFFSET] = 0.0;
  }
  joseph<N>(st.P, K, f, r_eff);
  for (int p = 0; p < N; ++p) st.theta[p] += K[p] * r;
  // the noise: from rows the detector tests, frozen while a change builds up (any CUSUM above h / 2; rotation
  // rows also while C_ch's window is open)
  if (tested && gmax < 0.5 * settings_.threshold && !(cls == 2 && std::max(st.g[2], st.g[3]) > kRestart)) {
    const double lam = std::max(1.0 / (st.n_rows[kRowKinds + cls] + 1.0), dt_ / settings_.noise_time);
    st.R[cls] += lam * (r * r - st.R[cls]);
  }
  st.n_rows[kRowKinds + cls] += 1.0;
  st.n_rows[c - 1] += 1.0;
  if (warm && excited[cls == 2 ? 1 : 0]) st.n_rows[kTested + c - 1] += 1.0;  // a row its CUSUM ran on
  detect<N>(out);
}

// _kernels._detect: CUSUMs above the threshold are a payload change: m_ch and C_ch (and m_ch y_c) reset from
// the window of the highest of them, one event per parameter whose CUSUM fired; then every CUSUM restarts.
template <int N>
void PayloadTracker::detect(TrackerOutput& out) noexcept {
  TrackerStateOf<N>& st = state_of<N>();
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
  reset_payload<N>(st.theta, st.P, st.Iw[best], st.bw[best], reset_var_, st.n_rows,
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
