// agvdyn_ff::PayloadTracker: online estimate of the payload-dependent parameters m_ch and C_ch (and,
// with TrackerSettings::com_offset, the centre-of-mass offset y_c) with change detection, the C++ twin
// of agvdyn.online.tracker (the reference; its module docstring
// states the equations, the state and the constants; docs/online.md, docs/cpp.md).
//
// The tracker consumes the causal rows of eq. (19) that agvdyn.online.rows builds (one per sample,
// or none): the row's kind (chassis coordinate x sign of its velocity), the regressor entries of
// m_ch and C_ch, and the right-hand side with every held parameter's contribution removed,
//
//   z = phi_m m_ch + phi_C C_ch + b_kind + noise    (+ phi_y m_ch y_c with com_offset).
//
// Per row: a Kalman filter with a random walk over (m_ch, C_ch, six row biases), information
// gating (a parameter learns, and its covariance grows, only from rows that excite it), a
// directional (Schmidt-type) update in Joseph form, the residual noise estimated online from the rows
// the detector tests (per noise class: straight x_ch, y_ch, gamma_ch and car-like x_ch rows), residual
// correlation in the row weight; four CUSUMs (m_ch from translation
// rows, C_ch from rotation rows, both signs) whose alarm is a payload change: m_ch, C_ch and the row
// biases learnt from few rows are re-estimated together from the rows since the CUSUM's start, with
// fresh priors (PX4-style covariance reset). With com_offset a ninth state, m_ch y_c, is learnt from
// the car-like rows (phi_y != 0; gated like the others), reset with m_ch and C_ch, and reported as
// y_c = (m_ch y_c) / m_ch with a delta-method std (infinite until a row informs it); x_c cancels in
// every motion mode and is not tracked. Without com_offset the arithmetic is that of eight states.
//
// create() checks the settings once; update() is the per-sample call: fixed-size Eigen types, no
// heap allocation, no exceptions, a Status for invalid input. The arithmetic follows the Python
// kernels (agvdyn/online/_kernels.py) operation by operation, so both give the same numbers to
// round-off (tests: cpp/tests/tracker_vectors.json, 1e-9 relative).
#pragma once

#include <agvdyn_ff/feedforward.hpp>

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <limits>

namespace agvdyn::ff {

/// Number of tracker states: m_ch, C_ch and the biases of the six kinds of row.
constexpr int kTrackerStates = 8;
/// With TrackerSettings::com_offset one more, m_ch y_c, at index kOffsetState.
constexpr int kOffsetStates = kTrackerStates + 1;
constexpr int kOffsetState = kTrackerStates;
using TrackerVector = Eigen::Matrix<double, kTrackerStates, 1>;
using TrackerMatrix = Eigen::Matrix<double, kTrackerStates, kTrackerStates>;
/// Kinds of row (RowKind: 1..8) and noise classes (x_ch straight, y_ch, gamma_ch, x_ch car-like).
constexpr int kRowKinds = 8;
constexpr int kNoiseClasses = 4;
/// Row counts of the state: per kind, per noise class, then the tested rows per kind (rows a CUSUM ran on).
constexpr int kTrackerCounts = 2 * kRowKinds + kNoiseClasses;

/// The whole state of a tracker of N states (agvdyn.online.tracker.TrackerState): CUSUM index c = 2 i + s
/// for parameter i (0: m_ch, 1: C_ch) and sign s (0: +, 1: -). Each size has its own storage (the
/// paper's eight states keep their 8 x 8 layout: the same arithmetic, as fast).
template <int N>
struct TrackerStateOf {
  using Vector = Eigen::Matrix<double, N, 1>;
  using Matrix = Eigen::Matrix<double, N, N>;
  Vector theta = Vector::Zero();                 ///< m_ch, C_ch, biases of x_ch+, x_ch-, y_ch+, y_ch-, gamma_ch+, gamma_ch-[, m_ch y_c]
  Matrix P = Matrix::Zero();                     ///< covariance of theta
  Eigen::Vector4d R = Eigen::Vector4d::Zero();   ///< residual variance per noise class: x_ch straight, y_ch, gamma_ch, x_ch car-like
  /// rows per kind (8), per noise class (4), tested per kind (8: rows a CUSUM ran on)
  Eigen::Matrix<double, kTrackerCounts, 1> n_rows = Eigen::Matrix<double, kTrackerCounts, 1>::Zero();
  std::array<double, 4> g{};                     ///< CUSUMs
  std::array<std::int64_t, 4> start{};           ///< their window's first sample
  std::array<Matrix, 4> Iw{};                    ///< window information f f^T / R_eff
  std::array<Vector, 4> bw{};                    ///< window f z / R_eff
  std::int64_t sample = 0;                       ///< samples since create() or begin_log()
};

/// Kind of a row (agvdyn.online.rows.ROW_KINDS): the chassis coordinate of the row's motion mode and
/// the sign of its velocity; none: no row at this sample. x_car_plus, x_car_minus: the x_ch rows of
/// car-like motion (x_plus, x_minus: of straight motion): the biases of x_plus and x_minus, a noise level of
/// their own (their yaw column misfits where the tyres scrub in turns).
enum class RowKind : int {
  none = 0, x_plus = 1, x_minus = 2, y_plus = 3, y_minus = 4, gamma_plus = 5, gamma_minus = 6, x_car_plus = 7,
  x_car_minus = 8
};

/// Label as in ROW_KINDS: "none", "x_ch+", "x_ch-", "y_ch+", "y_ch-", "gamma_ch+", "gamma_ch-", "x_ch+ car-like",
/// "x_ch- car-like"; "?" otherwise.
const char* label(RowKind kind) noexcept;

/// Constants of the tracker, defaults and meaning as agvdyn.online.TrackerSettings (relative ones
/// are fractions of the identified values; the row rules of the Python settings belong to the rows).
struct TrackerSettings {
  double change_size = 0.1;            ///< delta: the step each CUSUM looks for, x value
  double gate = 1.0;                   ///< excited when |phi_i| delta_i >= gate sqrt(R)
  double correlation = 150.0;          ///< n_corr of translation rows (samples)
  double rotation_correlation = 300.0; ///< n_corr of rotation rows (samples)
  double threshold = 8.0;              ///< h: CUSUM alarm level
  double random_walk = 1e-3;           ///< q = (random_walk x value)^2 per s
  double bias_walk = 0.3;              ///< q_b = bias_walk^2 per s (N or N m)
  double reset_std = 0.5;              ///< variance after a reset (prior): (reset_std x value)^2; cap of P_ii
  double noise_time = 30.0;            ///< tau_R (s) of the noise estimate
  int warm_rows = 250;                 ///< rows of a kind before its CUSUMs run (and its rows teach the noise)
  double initial_std = 0.02;           ///< least initial std, x value
  double bias_std = 30.0;              ///< initial std of the row biases
  double twin_bias_std = 5.0;          ///< a new kind's bias starts at its warm twin's (other sign), + this std
  double noise = 25.0;                 ///< initial residual variance R
  bool com_offset = false;             ///< track m_ch y_c (a ninth state) from the car-like rows
  double offset_change = 0.05;         ///< m: y_c step of the gate (excited when |phi_y| change m_ch >= gate sqrt(R))
  double offset_std = 0.3;             ///< m: y_c's prior std (start without a given std, reset; cap of its variance)
  double offset_walk = 1e-3;           ///< m/sqrt(s): y_c's random walk
};

/// One causal row (agvdyn.online.rows.OnlineRows at one sample).
struct TrackerRow {
  RowKind kind = RowKind::none;
  double phi_m = 0;   ///< regressor entry of m_ch
  double phi_C = 0;   ///< regressor entry of C_ch
  double z = 0;       ///< right-hand side less the held parameters' part
  double phi_y = 0;   ///< regressor entry of m_ch y_c (com_offset; nonzero in car-like rows only)
};

/// A detected change (a CUSUM above the threshold): sample indices since create() or begin_log().
struct TrackerEvent {
  int parameter = 0;          ///< 0: m_ch, 1: C_ch
  int sign = 0;               ///< +1 or -1: the direction of the step the CUSUM found
  std::int64_t sample = 0;    ///< the sample whose row crossed the threshold
  std::int64_t start = 0;     ///< the CUSUM's start: the estimated change (before the rows' delay)
  double before = 0, before_var = 0;   ///< estimate and variance before the reset
  double after = 0, after_var = 0;     ///< after the reset (from the rows since start)
};

/// What update() returns for one sample.
struct TrackerOutput {
  Vector2 estimate = Vector2::Zero();   ///< (m_ch, C_ch)
  Vector2 std = Vector2::Zero();        ///< their standard deviations
  double nis = 0;                       ///< normalised innovation squared; NaN without a row
  int event = 0;                        ///< bit 0: m_ch changed, bit 1: C_ch changed (this sample)
  int n_events = 0;                     ///< entries of events filled (0, 1 or 2)
  std::array<TrackerEvent, 2> events{};
  double y_c = std::numeric_limits<double>::quiet_NaN();      ///< com_offset: (m_ch y_c) / m_ch; NaN without
  double y_c_std = std::numeric_limits<double>::infinity();   ///< its delta-method std; inf until informed
};

/// Online tracker of m_ch and C_ch (see the head of this file). Copyable; not thread-safe (one
/// tracker per vehicle, updated from one thread).
class PayloadTracker {
 public:
  /// The state without com_offset (eight states) and with it (nine: m_ch y_c last).
  using State = TrackerStateOf<kTrackerStates>;
  using OffsetState = TrackerStateOf<kOffsetStates>;

  /// A tracker starting at the identified values nominal = (m_ch, C_ch) (> 0) with their stds
  /// (>= 0; at least initial_std x value is used), for rows every dt seconds (> 0).
  /// Status::invalid_model when a number is not finite or out of range (settings: every one > 0,
  /// warm_rows >= 0), as Python's TrackerSettings.
  static Status create(const Vector2& nominal, const Vector2& nominal_std, double dt, const TrackerSettings& settings,
                       PayloadTracker* tracker) noexcept;
  /// With com_offset: the start of y_c (m, finite) and its std (m; inf or NaN: none given, the prior
  /// offset_std; else at least offset_change), as agvdyn.online.tracker.TrackerState.initial.
  static Status create(const Vector2& nominal, const Vector2& nominal_std, double y_c, double y_c_std, double dt,
                       const TrackerSettings& settings, PayloadTracker* tracker) noexcept;

  /// One sample: the row's update when it has one (kind != none), detection and reset; out gets
  /// the estimates after it. The per-sample call: no heap allocation, no exceptions.
  /// Status::unknown_row_kind (kind not in 0..8) or non_finite_input (NaN or infinity in phi_m,
  /// phi_C, z, and phi_y with com_offset): the row is refused and the sample counts as one without a row (out has the current
  /// estimates, nis NaN, no event).
  Status update(const TrackerRow& row, TrackerOutput& out) noexcept;

  /// A new log of the same vehicle (agvdyn.online.track): the CUSUMs restart at zero and samples
  /// are counted from 0 again; estimates, covariance and noise carry over.
  void begin_log() noexcept;

  /// Current estimates (m_ch, C_ch) and their stds.
  Vector2 estimate() const noexcept {
    return settings_.com_offset ? Vector2(offset_state_.theta.head<2>()) : Vector2(state_.theta.head<2>());
  }
  Vector2 std() const noexcept;
  /// Number of states: kTrackerStates, kTrackerStates + 1 with com_offset.
  int states() const noexcept { return settings_.com_offset ? kOffsetStates : kTrackerStates; }
  /// Changes detected since create() (not reset by begin_log()).
  std::int64_t event_count() const noexcept { return event_count_; }

  /// The state of a tracker without com_offset (state()) or with it (offset_state()); the other is unused.
  const State& state() const noexcept { return state_; }
  const OffsetState& offset_state() const noexcept { return offset_state_; }
  /// Replace the state (e.g. carried from Python's TrackerState or a previous run);
  /// Status::non_finite_input when theta, P, R, n_rows, g, Iw or bw hold NaN or infinity,
  /// Status::invalid_model when its size is not the tracker's (states()).
  Status set_state(const State& state) noexcept;
  Status set_state(const OffsetState& state) noexcept;

  const TrackerSettings& settings() const noexcept { return settings_; }
  const Vector2& nominal() const noexcept { return nominal_; }
  double dt() const noexcept { return dt_; }

 private:
  template <int N>
  void update_states(const TrackerRow& row, TrackerOutput& out) noexcept;
  template <int N>
  void detect(TrackerOutput& out) noexcept;
  void report(TrackerOutput& out) const noexcept;
  template <int N>
  void initial_state(TrackerStateOf<N>& st, const Vector2& nominal, const Vector2& nominal_std) const noexcept;
  template <int N>
  TrackerStateOf<N>& state_of() noexcept {
    if constexpr (N == kTrackerStates) {
      return state_;
    } else {
      return offset_state_;
    }
  }

  TrackerSettings settings_{};
  State state_{};
  OffsetState offset_state_{};
  Vector2 nominal_ = Vector2::Zero();
  double dt_ = 0;
  // constants of the Python kernel (TrackerSettings.constants)
  // (m_ch, C_ch, m_ch y_c): the last with com_offset, from offset_change, offset_walk, offset_std x m_ch
  Eigen::Vector3d delta_ = Eigen::Vector3d::Zero();      // change_size x nominal
  Eigen::Vector3d q_ = Eigen::Vector3d::Zero();          // (random_walk x nominal)^2 dt
  Eigen::Vector3d reset_var_ = Eigen::Vector3d::Zero();  // (reset_std x nominal)^2
  double q_b_ = 0;                       // bias_walk^2
  double bias_var_ = 0;                  // bias_std^2: a young row bias's variance after a reset
  double twin_var_ = 0;                  // twin_bias_std^2: added to a twin's variance for a new kind's bias
  std::int64_t event_count_ = 0;
};

}  // namespace agvdyn::ff
