// agvdyn_ff: real-time feed-forward motor torques of eq. (21) for the passively steered 4WD
// quasi-omnidirectional platform (Pucher, Gattringer, Mueller), the C++ twin of
// agvdyn.dynamics.feedforward_torques (the reference implementation).
//
//   u = minimum-norm solution of  N^T B u = N^T Theta(q_dot, q_ddot) p
//
// with q_dot = H_k s_dot, q_ddot = dH_k/dt s_dot + H_k s_ddot (eq. 4, 20), Theta the regressor
// of eq. (16), p the 11 parameters in the order of eq. (18), B = i_G [0; I_4] (eq. 17) and N the
// basis of every velocity the configuration admits (steering either side at rest, plus the
// chassis motion of modes 2, 3, 4 and straight). Mode 3 puts the steering force that the lateral
// force implies on the side whose mechanical stop absorbs it (see docs/model.md).
//
// Conventions (shared/PLATFORM.md): alpha = (alpha_l, alpha_r), the front wheels' headings;
// q = (x_ch, y_ch, gamma_ch, alpha_l, alpha_r, beta_fl, beta_rl, beta_fr, beta_rr) with body-frame
// chassis velocities; motor torques u in wheel order fl, rl, fr, rr (motor side).
//
// A Model is built once (checks its invariants, precomputes the constant kinematic models and
// right inverses); Model::feedforward is the per-step call: fixed-size Eigen types on the stack,
// no heap allocation, no exceptions, an error code for invalid input.
#pragma once

#include <Eigen/Core>

#include <array>
#include <cstddef>

namespace agvdyn::ff {

using Vector2 = Eigen::Vector2d;
using Vector4 = Eigen::Vector4d;
using Vector9 = Eigen::Matrix<double, 9, 1>;
using Vector11 = Eigen::Matrix<double, 11, 1>;

/// Motion modes of eq. (9); straight is mode 2 with alpha_v = 0 (label "2s").
enum class Mode : int { parking = 1, car_like = 2, lateral = 3, rotation = 4, straight = 5 };

/// Number of generalized velocities s_k_dot of a mode (eq. 10-13): 2 in modes 1 and 2, else 1.
constexpr int dof(Mode mode) noexcept {
  return (mode == Mode::parking || mode == Mode::car_like) ? 2 : 1;
}

/// Label as in Python's Mode.label: "1", "2", "3", "4", "2s"; "?" for an invalid value.
const char* label(Mode mode) noexcept;

/// Mode of a label ("1", "2", "3", "4", "2s", "5", "straight", "parking", "car-like", "lateral",
/// "rotation", ...; the labels Python's Mode.from_label accepts). False for anything else.
bool mode_from_label(const char* text, Mode* mode) noexcept;

/// Outcome of a call. Everything but ok leaves the torques at zero (PayloadTracker: the state unchanged).
enum class Status : int {
  ok = 0,
  unknown_mode = 1,        ///< mode is not one of 1, 2, 3, 4, straight
  non_finite_input = 2,    ///< NaN or infinity in alpha, s_dot or s_ddot
  beyond_stop = 3,         ///< |alpha| > pi/2 + stop_tolerance (mechanical stops)
  not_in_mode = 4,         ///< alpha is not in the mode within mode_tolerance (eq. 9)
  singular = 5,            ///< N^T B has no full rank (a = 0: the wheels cannot steer)
  invalid_model = 6,       ///< geometry, parameters or settings break their invariants
  unknown_row_kind = 7,    ///< PayloadTracker: a row kind not in 0..6 (tracker.hpp)
};

/// Short name of a status ("ok", "not_in_mode", ...).
const char* to_string(Status status) noexcept;

/// Geometry (PLATFORM.md): l, b distances of the steering axes (m), a offset of the contact point
/// along the axle, positive outboard (m), r wheel radius (m), i_G gear ratio.
struct Geometry {
  double l = 1.2;
  double b = 0.8;
  double a = 0.05;
  double r = 0.1;
  double i_G = 25.0;
};

/// The 11 parameters p of eq. (18), SI units, in this order.
struct Parameters {
  double C_l = 0, d_vl = 0, d_cl = 0, C_r = 0, d_vr = 0, d_cr = 0, m_ch = 0, C_ch = 0, d_vw = 0, d_cw = 0, B_w = 0;

  static constexpr std::array<const char*, 11> names = {
      "C_l", "d_vl", "d_cl", "C_r", "d_vr", "d_cr", "m_ch", "C_ch", "d_vw", "d_cw", "B_w"};
  Vector11 to_vector() const noexcept;
  static Parameters from_vector(const Vector11& p) noexcept;
  /// The paper's Table 2 with B_w = 0.121 (PLATFORM.md "Reference values").
  static Parameters paper() noexcept;
};

/// The model beyond the paper (issue 30; agvdyn.model_spec.ModelParameters), default the paper's model:
///  * stribeck: per joint group g (0 left steering, 1 right steering, 2 wheels) the friction of a joint
///    rate w is d_v w + [d_c + (d_s - d_c) exp(-(w / w_s)^2)] tanh(w / epsilon), with d_s the static
///    (breakaway) level d_sl, d_sr, d_sw (N m) and w_s the Stribeck velocity w_sl, w_sr, w_sw (rad/s, > 0);
///  * com_offset: the chassis centre of mass at (x_c, y_c) in the chassis frame (m); with a_x, a_y of
///    eq. (16), w = gamma_dot, m = m_ch the chassis rows gain -m x_c w^2 - m y_c w_dot,
///    m x_c w_dot - m y_c w^2 and m x_c a_y - m y_c a_x (C_ch stays about the reference point);
///  * delay_s: the logged torque column lags the angles by delay_s (the torque logged at t acted at
///    t - delay_s). It is carried, not applied: it does not change the torques, only when they must be
///    commanded (a command column that leads, delay_s < 0, is issued -delay_s early; docs/cpp.md).
struct Extension {
  bool stribeck = false;
  std::array<double, 3> d_s{{0.0, 0.0, 0.0}};   ///< d_sl, d_sr, d_sw (N m)
  std::array<double, 3> w_s{{1.0, 1.0, 1.0}};   ///< w_sl, w_sr, w_sw (rad/s)
  bool com_offset = false;
  double x_c = 0.0, y_c = 0.0;                  ///< m
  double delay_s = 0.0;                         ///< s

  /// Names of the extra parameters in parameter files (agvdyn.model_spec.EXTRA_NAMES).
  static constexpr std::array<const char*, 8> names = {"d_sl", "d_sr", "d_sw", "w_sl", "w_sr", "w_sw", "x_c", "y_c"};
  /// Breakaway friction or an offset: forces beyond those of eq. (16).
  bool changes_forces() const noexcept { return stribeck || com_offset; }
};

/// Tuning constants, defaults as in Python (platform.EPSILON, kinematics.MODE_TOLERANCE, STOP_TOLERANCE).
struct Settings {
  double epsilon = 0.01;          ///< Coulomb friction d_c tanh(velocity / epsilon), rad/s
  double mode_tolerance = 0.02;   ///< rad, eq. (9) with measured angles
  double stop_tolerance = 1e-6;   ///< rad beyond the stops at +-pi/2
};

/// Desired motion of one control step in mode k. Only the first dof(k) entries of s_dot and
/// s_ddot are used: mode 1 (alpha_l, alpha_r), mode 2 (alpha_v, x_ch), mode 3 y_ch, mode 4
/// gamma_ch, straight x_ch. The steering rates are part of s_dot (mode 1: alpha_dot; mode 2:
/// alpha_dot = f_ICR'(alpha_v) alpha_v_dot; zero in modes 3, 4 and straight).
struct Setpoint {
  Mode mode = Mode::parking;
  Vector2 alpha = Vector2::Zero();
  Vector2 s_dot = Vector2::Zero();
  Vector2 s_ddot = Vector2::Zero();
};

/// Joint velocities and accelerations of a setpoint, eq. (4) and (20).
struct JointMotion {
  Vector9 q_dot = Vector9::Zero();
  Vector9 q_ddot = Vector9::Zero();
};

/// Constant model description: geometry, parameters, settings and everything precomputed from
/// them. Build with Model::create; copyable, immutable, safe to share between threads.
class Model {
 public:
  /// A model, or Status::invalid_model when l, b, r, i_G are not finite and > 0, |a| >= min(l, b)/2,
  /// a parameter is not finite, or epsilon, mode_tolerance are not > 0 (as Python's Geometry).
  static Status create(const Geometry& geometry, const Parameters& parameters, const Settings& settings,
                       Model* model) noexcept;

  /// The same with the model beyond the paper; Status::invalid_model also when an extension value is
  /// not finite or a Stribeck velocity of a stribeck model is not > 0.
  static Status create(const Geometry& geometry, const Parameters& parameters, const Extension& extension,
                       const Settings& settings, Model* model) noexcept;

  /// This model with another extension (no allocation); Status::invalid_model (out untouched) as create.
  Status with_extension(const Extension& extension, Model* out) const noexcept;

  /// This model with other parameters (the geometry's precomputed parts and the extension kept), e.g.
  /// the m_ch, C_ch of a PayloadTracker: no allocation, no exceptions, cheap enough per control step (a copy).
  /// Status::invalid_model (out untouched) when a parameter is not finite.
  Status with_parameters(const Parameters& parameters, Model* out) const noexcept;

  /// Motor torques u (fl, rl, fr, rr; N m, motor side) of eq. (21), with the forces of the extended
  /// model when it has an extension. The per-step call: no heap allocation, no exceptions. On any
  /// status but ok, u is zero (and motion, when given, too).
  Status feedforward(const Setpoint& setpoint, Vector4& u, JointMotion* motion = nullptr) const noexcept;

  /// q_dot and q_ddot of a setpoint, eq. (4) and (20), with the same checks as feedforward.
  Status joint_motion(const Setpoint& setpoint, JointMotion& motion) const noexcept;

  /// Least-squares generalized velocities s_dot = H_k^+ q_dot of a joint velocity in mode k (the
  /// inverse of eq. 4 for an admissible q_dot); entries beyond dof(k) are zero.
  Status generalized_velocities(Mode mode, const Vector2& alpha, const Vector9& q_dot, Vector2& s_dot) const noexcept;

  const Geometry& geometry() const noexcept { return geometry_; }
  const Parameters& parameters() const noexcept { return parameters_; }
  const Settings& settings() const noexcept { return settings_; }
  const Extension& extension() const noexcept { return extension_; }

 private:
  Status check(const Setpoint& setpoint) const noexcept;
  // check, then H_k and the joint motion of eq. (4), (20); zero motion on a bad setpoint
  Status prepare(const Setpoint& setpoint, Eigen::Matrix<double, 9, 2>& H, JointMotion& motion) const noexcept;
  void kinematics(Mode mode, const Vector2& alpha, Eigen::Matrix<double, 9, 2>& H,
                  Eigen::Matrix<double, 9, 2>& dH) const noexcept;
  void motion(const Setpoint& setpoint, const Eigen::Matrix<double, 9, 2>& H, const Eigen::Matrix<double, 9, 2>& dH,
              JointMotion& motion) const noexcept;
  Vector9 forces(const JointMotion& motion) const noexcept;
  // the forces the extension adds to those of eq. (16) (agvdyn.dynamics_extended.extension_forces);
  // coulomb[i] = tanh(q_dot[i] / epsilon) for i = 3..8
  Vector9 extension_forces(const JointMotion& motion, const double* coulomb) const noexcept;

  Geometry geometry_{};
  Parameters parameters_{};
  Settings settings_{};
  Extension extension_{};
  Vector11 p_ = Vector11::Zero();
  double max_virtual_angle_ = 0;              // arctan(l/b)
  Eigen::Matrix<double, 9, 2> H1_ = Eigen::Matrix<double, 9, 2>::Zero();   // mode 1, steering at rest
  // Chassis column of the constant modes 3, 4, straight (index 0, 1, 2).
  std::array<Vector9, 3> chassis_{};
  // Constant right inverses of N^T B: mode 1 (4x2) and modes 3, 4, straight (4x3, index 0, 1, 2);
  // mode 3's is the pseudoinverse of its rank-2 N^T B for consistent targets.
  Eigen::Matrix<double, 4, 2> P1_ = Eigen::Matrix<double, 4, 2>::Zero();
  std::array<Eigen::Matrix<double, 4, 3>, 3> P_{};
  bool steerable_ = false;   // a != 0: N^T B has full row rank in modes 1, 2, 4, straight
};

}  // namespace agvdyn::ff
