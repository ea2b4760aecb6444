// Feed-forward of eq. (21); see include/agvdyn_ff/feedforward.hpp. Every formula mirrors its
// Python reference, named in the comments (agvdyn.kinematics, agvdyn.dynamics).
#include "agvdyn_ff/feedforward.hpp"

#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace agvdyn::ff {
namespace {

constexpr double kPi = 3.14159265358979323846;

using Matrix92 = Eigen::Matrix<double, 9, 2>;

bool finite(double x) noexcept { return std::isfinite(x); }

int constant_index(Mode mode) noexcept {  // modes with a constant chassis column
  switch (mode) {
    case Mode::lateral: return 0;
    case Mode::rotation: return 1;
    case Mode::straight: return 2;
    default: return -1;
  }
}

bool valid(Mode mode) noexcept {
  const int m = static_cast<int>(mode);
  return m >= 1 && m <= 5;
}

// Fixed steering angles of modes 3, 4, straight (kinematics.nominal_steering).
Vector2 nominal_steering(const Geometry& g, Mode mode) noexcept {
  switch (mode) {
    case Mode::lateral: return Vector2(-kPi / 2, kPi / 2);
    case Mode::rotation: {
      const double rot = std::atan2(g.l, g.b);
      return Vector2(-rot, rot);
    }
    default: return Vector2::Zero();
  }
}

// (alpha_v, residual) of one configuration, k = b/l: kinematics.icr_state.
void icr_state(double k, double alpha_l, double alpha_r, double* alpha_v, double* residual) noexcept {
  const double sl = std::sin(alpha_l), cl = std::cos(alpha_l);
  const double sr = std::sin(alpha_r), cr = std::cos(alpha_r);
  const double av_l = std::atan2(sl, cl + k * sl);
  const double av_r = std::atan2(sr, cr - k * sr);
  *alpha_v = 0.5 * (av_l + av_r);
  double x = std::fmod(av_l - av_r + kPi / 2, kPi);  // Python's floor modulo
  if (x < 0) x += kPi;
  *residual = x - kPi / 2;
}

// H_2 and dH_2/d alpha_v at one virtual angle: kinematics.car_like_model_into.
void car_like_model(const Geometry& g, double alpha_v, Matrix92& H, Matrix92& dH) noexcept {
  const double l = g.l, b = g.b, a = g.a, r = g.r;
  const double k = b / l;
  const double s = std::sin(alpha_v), c = std::cos(alpha_v);
  const double s2 = 2 * s * c, c2 = c * c - s * s;
  const double D_l = 1 - k * s2 + k * k * s * s;
  const double D_r = 1 + k * s2 + k * k * s * s;
  const double root_l = std::sqrt(D_l), root_r = std::sqrt(D_r);
  const double cos_l = (c - k * s) / root_l, sin_l = s / root_l;
  const double cos_r = (c + k * s) / root_r, sin_r = s / root_r;
  const double d1_l = 1 / D_l, d1_r = 1 / D_r;
  const double d2_l = (2 * k * c2 - k * k * s2) / (D_l * D_l);
  const double d2_r = (-2 * k * c2 - k * k * s2) / (D_r * D_r);
  const double kappa = 2 * s / (c * l);
  const double dkappa = 2 / (l * c * c);
  H.setZero();
  dH.setZero();
  H(3, 0) = d1_l;
  H(4, 0) = d1_r;
  dH(3, 0) = d2_l;
  dH(4, 0) = d2_r;
  H(0, 1) = 1.0;
  H(2, 1) = kappa;
  dH(2, 1) = dkappa;
  for (int i = 0; i < 4; ++i) {
    const bool left = i < 2;
    const double sigma = (i % 2 == 0) ? 1.0 : -1.0;  // rear wheels mirrored: theta = sigma * alpha
    const double side = left ? 1.0 : -1.0;
    const double cx = (i % 2 == 0) ? l / 2 : -l / 2;
    const double cy = left ? b / 2 : -b / 2;
    const double d1 = left ? d1_l : d1_r;
    const double d2 = left ? d2_l : d2_r;
    const double ct = left ? cos_l : cos_r;
    const double st = sigma * (left ? sin_l : sin_r);
    const double vx = 1 - kappa * cy, vy = kappa * cx;
    H(5 + i, 0) = -side * a * sigma * d1 / r;
    dH(5 + i, 0) = -side * a * sigma * d2 / r;
    H(5 + i, 1) = (ct * vx + st * vy - side * a * kappa) / r;
    dH(5 + i, 1) = (sigma * d1 * (-st * vx + ct * vy) - ct * dkappa * cy + st * dkappa * cx - side * a * dkappa) / r;
  }
}

// One admissible velocity from a chassis twist and steering rates at steering angles alpha:
// kinematics._column / _wheel_rates.
Vector9 admissible_column(const Geometry& g, const Vector2& alpha, const Eigen::Vector3d& twist,
                          const Vector2& alpha_dot) noexcept {
  Vector9 q = Vector9::Zero();
  q.head<3>() = twist;
  q.segment<2>(3) = alpha_dot;
  for (int i = 0; i < 4; ++i) {
    const bool left = i < 2;
    const double sigma = (i % 2 == 0) ? 1.0 : -1.0;
    const double side = left ? 1.0 : -1.0;
    const double cx = (i % 2 == 0) ? g.l / 2 : -g.l / 2;
    const double cy = left ? g.b / 2 : -g.b / 2;
    const double theta = sigma * alpha[left ? 0 : 1];
    const double theta_dot = sigma * alpha_dot[left ? 0 : 1];
    const double vx = twist[0] - twist[2] * cy;
    const double vy = twist[1] + twist[2] * cx;
    q[5 + i] = (std::cos(theta) * vx + std::sin(theta) * vy - side * g.a * (twist[2] + theta_dot)) / g.r;
  }
  return q;
}

}  // namespace

const char* label(Mode mode) noexcept {
  switch (mode) {
    case Mode::parking: return "1";
    case Mode::car_like: return "2";
    case Mode::lateral: return "3";
    case Mode::rotation: return "4";
    case Mode::straight: return "2s";
  }
  return "?";
}

bool mode_from_label(const char* text, Mode* mode) noexcept {
  if (text == nullptr || mode == nullptr) return false;
  // trim and lower-case into a small buffer (kinematics._LABELS)
  while (*text == ' ' || *text == '\t') ++text;
  char key[16];
  std::size_t n = 0;
  for (; text[n] != '\0' && n < sizeof key - 1; ++n) {
    const char ch = text[n];
    key[n] = (ch >= 'A' && ch <= 'Z') ? static_cast<char>(ch - 'A' + 'a') : ch;
  }
  if (text[n] != '\0') return false;
  while (n > 0 && (key[n - 1] == ' ' || key[n - 1] == '\t' || key[n - 1] == '\r' || key[n - 1] == '\n')) --n;
  key[n] = '\0';
  struct Entry { const char* key; Mode mode; };
  static constexpr Entry table[] = {
      {"1", Mode::parking},    {"parking", Mode::parking},   {"alignment", Mode::parking},
      {"2", Mode::car_like},   {"car", Mode::car_like},      {"car-like", Mode::car_like},
      {"car_like", Mode::car_like},
      {"3", Mode::lateral},    {"lateral", Mode::lateral},
      {"4", Mode::rotation},   {"rotation", Mode::rotation},
      {"2s", Mode::straight},  {"straight", Mode::straight}, {"5", Mode::straight},
  };
  for (const Entry& e : table) {
    if (std::strcmp(key, e.key) == 0) {
      *mode = e.mode;
      return true;
    }
  }
  return false;
}

const char* to_string(Status status) noexcept {
  switch (status) {
    case Status::ok: return "ok";
    case Status::unknown_mode: return "unknown_mode";
    case Status::non_finite_input: return "non_finite_input";
    case Status::beyond_stop: return "beyond_stop";
    case Status::not_in_mode: return "not_in_mode";
    case Status::singular: return "singular";
    case Status::invalid_model: return "invalid_model";
    case Status::unknown_row_kind: return "unknown_row_kind";
  }
  return "unknown_status";
}

Vector11 Parameters::to_vector() const noexcept {
  Vector11 p;
  p << C_l, d_vl, d_cl, C_r, d_vr, d_cr, m_ch, C_ch, d_vw, d_cw, B_w;
  return p;
}

Parameters Parameters::from_vector(const Vector11& p) noexcept {
  Parameters out;
  out.C_l = p[0]; out.d_vl = p[1]; out.d_cl = p[2]; out.C_r = p[3]; out.d_vr = p[4]; out.d_cr = p[5];
  out.m_ch = p[6]; out.C_ch = p[7]; out.d_vw = p[8]; out.d_cw = p[9]; out.B_w = p[10];
  return out;
}

Parameters Parameters::paper() noexcept {
  Vector11 p;
  p << 0.3342, 4.4649, 12.9458, 0.4501, 2.4820, 17.1071, 842.0684, 286.5955, 0.7316, 3.9656, 0.121;
  return from_vector(p);
}

namespace {

// Finite values, and Stribeck velocities > 0 when the model has breakaway friction.
bool valid(const Extension& e) noexcept {
  for (int g = 0; g < 3; ++g) {
    if (!finite(e.d_s[g]) || !finite(e.w_s[g])) return false;
    if (e.stribeck && !(e.w_s[g] > 0)) return false;
  }
  return finite(e.x_c) && finite(e.y_c) && finite(e.delay_s);
}

}  // namespace

Status Model::create(const Geometry& g, const Parameters& parameters, const Extension& extension,
                     const Settings& settings, Model* model) noexcept {
  if (model == nullptr || !valid(extension)) return Status::invalid_model;
  Model m;
  const Status status = create(g, parameters, settings, &m);
  if (status != Status::ok) return status;
  m.extension_ = extension;
  *model = m;
  return Status::ok;
}

Status Model::with_extension(const Extension& extension, Model* out) const noexcept {
  if (out == nullptr || !valid(extension)) return Status::invalid_model;
  if (out != this) *out = *this;
  out->extension_ = extension;
  return Status::ok;
}

Status Model::create(const Geometry& g, const Parameters& parameters, const Settings& settings,
                     Model* model) noexcept {
  if (model == nullptr) return Status::invalid_model;
  for (double v : {g.l, g.b, g.r, g.i_G}) {
    if (!finite(v) || !(v > 0)) return Status::invalid_model;
  }
  if (!finite(g.a) || !(std::abs(g.a) < std::min(g.l, g.b) / 2)) return Status::invalid_model;
  const Vector11 p = parameters.to_vector();
  if (!p.allFinite()) return Status::invalid_model;
  if (!finite(settings.epsilon) || !(settings.epsilon > 0) || !finite(settings.mode_tolerance) ||
      !(settings.mode_tolerance > 0) || !finite(settings.stop_tolerance) || !(settings.stop_tolerance >= 0)) {
    return Status::invalid_model;
  }
  Model m;
  m.geometry_ = g;
  m.parameters_ = parameters;
  m.settings_ = settings;
  m.p_ = p;
  m.max_virtual_angle_ = std::atan2(g.l, g.b);
  // H_1: steering either side at rest (kinematics._constant_model(PARKING)); theta does not matter.
  for (int j = 0; j < 2; ++j) {
    m.H1_.col(j) = admissible_column(g, Vector2::Zero(), Eigen::Vector3d::Zero(), Vector2::Unit(j));
  }
  m.steerable_ = g.a != 0.0;
  const Eigen::Matrix<double, 2, 4> M1 = g.i_G * m.H1_.bottomRows<4>().transpose();
  if (m.steerable_) m.P1_ = M1.transpose() * (M1 * M1.transpose()).inverse();
  const Eigen::Vector3d twists[3] = {Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitX()};
  const Mode modes[3] = {Mode::lateral, Mode::rotation, Mode::straight};
  for (int c = 0; c < 3; ++c) {
    m.chassis_[c] = admissible_column(g, nominal_steering(g, modes[c]), twists[c], Vector2::Zero());
    Eigen::Matrix<double, 9, 3> N;
    N << m.H1_, m.chassis_[c];
    const Eigen::Matrix<double, 3, 4> M = g.i_G * N.bottomRows<4>().transpose();
    if (modes[c] == Mode::lateral) {
      // rank 2: on the wheels h_y = (h_l + h_r) / a, so for the consistent targets of
      // feedforward() the pseudoinverse (numpy.linalg.pinv in Python) is the minimum-norm solution of
      // the first two rows, mode 1's right inverse. Without offset (a = 0) only the chassis row is left.
      m.P_[c].setZero();
      if (m.steerable_) {
        m.P_[c].leftCols<2>() = m.P1_;
      } else {
        m.P_[c].col(2) = M.row(2).transpose() / M.row(2).squaredNorm();
      }
    } else if (m.steerable_) {
      m.P_[c] = M.transpose() * (M * M.transpose()).inverse();
    } else {
      m.P_[c].setZero();
    }
  }
  *model = m;
  return Status::ok;
}

Status Model::with_parameters(const Parameters& parameters, Model* out) const noexcept {
  if (out == nullptr) return Status::invalid_model;
  const Vector11 p = parameters.to_vector();
  if (!p.allFinite()) return Status::invalid_model;
  if (out != this) *out = *this;
  out->parameters_ = parameters;
  out->p_ = p;
  return Status::ok;
}

Status Model::check(const Setpoint& sp) const noexcept {
  if (!valid(sp.mode)) return Status::unknown_mode;
  const int n = dof(sp.mode);
  if (!sp.alpha.allFinite() || !sp.s_dot.head(n).allFinite() || !sp.s_ddot.head(n).allFinite()) {
    return Status::non_finite_input;
  }
  const double stop = kPi / 2 + settings_.stop_tolerance;
  if (std::abs(sp.alpha[0]) > stop || std::abs(sp.alpha[1]) > stop) return Status::beyond_stop;
  const double tol = settings_.mode_tolerance;
  switch (sp.mode) {  // kinematics.check_mode
    case Mode::parking: return Status::ok;
    case Mode::car_like: {
      double av, residual;
      icr_state(geometry_.b / geometry_.l, sp.alpha[0], sp.alpha[1], &av, &residual);
      const bool ok = std::abs(av) <= max_virtual_angle_ + tol && std::abs(residual) <= tol;
      return ok ? Status::ok : Status::not_in_mode;
    }
    default: {
      const Vector2 err = (sp.alpha - nominal_steering(geometry_, sp.mode)).cwiseAbs();
      return err.maxCoeff() <= tol ? Status::ok : Status::not_in_mode;
    }
  }
}

void Model::kinematics(Mode mode, const Vector2& alpha, Matrix92& H, Matrix92& dH) const noexcept {
  if (mode == Mode::car_like) {
    double av, residual;
    icr_state(geometry_.b / geometry_.l, alpha[0], alpha[1], &av, &residual);
    av = std::min(std::max(av, -max_virtual_angle_), max_virtual_angle_);
    car_like_model(geometry_, av, H, dH);
    return;
  }
  dH.setZero();
  if (mode == Mode::parking) {
    H = H1_;
    return;
  }
  H.col(0) = chassis_[constant_index(mode)];
  H.col(1).setZero();
}

Vector9 Model::forces(const JointMotion& jm) const noexcept {
  // Theta(q_dot, q_ddot) p, eq. (16) (dynamics.regressor @ p)
  const Vector9& qd = jm.q_dot;
  const Vector9& qdd = jm.q_ddot;
  const Parameters& P = parameters_;
  const double eps = settings_.epsilon;
  Vector9 f;
  f[0] = P.m_ch * (qdd[0] - qd[1] * qd[2]);
  f[1] = P.m_ch * (qdd[1] + qd[0] * qd[2]);
  f[2] = (P.C_l + P.C_r + P.C_ch) * qdd[2];
  double coulomb[9];  // tanh(q_dot / epsilon) of the joints 3..8, shared with the breakaway terms
  for (int i = 3; i < 9; ++i) coulomb[i] = std::tanh(qd[i] / eps);
  f[3] = P.C_l * qdd[3] + P.d_vl * qd[3] + P.d_cl * coulomb[3];
  f[4] = P.C_r * qdd[4] + P.d_vr * qd[4] + P.d_cr * coulomb[4];
  for (int i = 5; i < 9; ++i) f[i] = P.B_w * qdd[i] + P.d_vw * qd[i] + P.d_cw * coulomb[i];
  if (extension_.changes_forces()) f += extension_forces(jm, coulomb);
  return f;
}

Vector9 Model::extension_forces(const JointMotion& jm, const double* coulomb) const noexcept {
  // agvdyn.dynamics_extended: breakaway_forces, then com_offset_forces (the same order of operations)
  const Vector9& qd = jm.q_dot;
  const Vector9& qdd = jm.q_ddot;
  const Extension& e = extension_;
  Vector9 out = Vector9::Zero();
  if (e.stribeck) {
    const double d_c[3] = {parameters_.d_cl, parameters_.d_cr, parameters_.d_cw};
    for (int i = 3; i < 9; ++i) {
      const int g = i < 5 ? i - 3 : 2;
      const double ratio = qd[i] / e.w_s[g];
      out[i] = (e.d_s[g] - d_c[g]) * std::exp(-(ratio * ratio)) * coulomb[i];
    }
  }
  if (e.com_offset) {
    const double m_x_c = parameters_.m_ch * e.x_c, m_y_c = parameters_.m_ch * e.y_c;
    const double w = qd[2], w_dot = qdd[2], w2 = w * w;
    const double a_x = qdd[0] - qd[1] * w, a_y = qdd[1] + qd[0] * w;
    out[0] += -m_x_c * w2 - m_y_c * w_dot;
    out[1] += m_x_c * w_dot - m_y_c * w2;
    out[2] += m_x_c * a_y - m_y_c * a_x;
  }
  return out;
}

void Model::motion(const Setpoint& sp, const Matrix92& H, const Matrix92& dH, JointMotion& jm) const noexcept {
  if (dof(sp.mode) == 2) {
    jm.q_dot.noalias() = H * sp.s_dot;
    jm.q_ddot.noalias() = H * sp.s_ddot;
    // mode 2: dH/dt = dH/d alpha_v * alpha_v_dot (kinematics.kinematic_model_dot); zero in mode 1
    if (sp.mode == Mode::car_like) jm.q_ddot.noalias() += (dH * sp.s_dot[0]) * sp.s_dot;
  } else {
    jm.q_dot = H.col(0) * sp.s_dot[0];
    jm.q_ddot = H.col(0) * sp.s_ddot[0];
  }
}

Status Model::prepare(const Setpoint& sp, Matrix92& H, JointMotion& jm) const noexcept {
  const Status status = check(sp);
  if (status != Status::ok) {
    jm.q_dot.setZero();
    jm.q_ddot.setZero();
    return status;
  }
  Matrix92 dH;
  kinematics(sp.mode, sp.alpha, H, dH);
  motion(sp, H, dH, jm);
  return Status::ok;
}

Status Model::joint_motion(const Setpoint& sp, JointMotion& jm) const noexcept {
  Matrix92 H;
  return prepare(sp, H, jm);
}

Status Model::feedforward(const Setpoint& sp, Vector4& u, JointMotion* out) const noexcept {
  JointMotion local;
  JointMotion& jm = out != nullptr ? *out : local;
  u.setZero();
  Matrix92 H;
  const Status status = prepare(sp, H, jm);
  if (status != Status::ok) return status;
  if (!steerable_ && sp.mode != Mode::lateral) {
    jm.q_dot.setZero();
    jm.q_ddot.setZero();
    return Status::singular;
  }
  const Vector9 f = forces(jm);
  // g = N^T f on the admissible basis N = [H_1, chassis column] (dynamics.feedforward_torques)
  const Vector2 g1 = H1_.transpose() * f;
  switch (sp.mode) {
    case Mode::parking:
      u.noalias() = P1_ * g1;
      break;
    case Mode::car_like: {
      // chassis column of H_2 at this configuration: minimum-norm u = M^T (M M^T)^-1 g
      Eigen::Matrix<double, 3, 4> M;
      M.topRows<2>() = geometry_.i_G * H1_.bottomRows<4>().transpose();
      M.row(2) = geometry_.i_G * H.col(1).tail<4>().transpose();
      const Eigen::Vector3d g(g1[0], g1[1], H.col(1).dot(f));
      const Eigen::Matrix3d MMt = M * M.transpose();  // symmetric positive definite for a != 0
      u.noalias() = M.transpose() * (MMt.inverse() * g);
      break;
    }
    case Mode::lateral: {
      // steering targets consistent with T_l + T_r = a F_y, pressing into the stops
      // (dynamics._lateral_steering_targets): left stop at -pi/2, right stop at +pi/2
      Eigen::Vector3d g(g1[0], g1[1], chassis_[0].dot(f));
      const double excess = geometry_.a * g[2] - (g[0] + g[1]);
      if (excess >= 0) g[1] += excess; else g[0] += excess;
      u.noalias() = P_[0] * g;
      break;
    }
    default: {
      const int c = constant_index(sp.mode);
      const Eigen::Vector3d g(g1[0], g1[1], chassis_[c].dot(f));
      u.noalias() = P_[c] * g;
      break;
    }
  }
  if (!u.allFinite()) {
    u.setZero();
    return Status::singular;
  }
  return Status::ok;
}

Status Model::generalized_velocities(Mode mode, const Vector2& alpha, const Vector9& q_dot,
                                     Vector2& s_dot) const noexcept {
  s_dot.setZero();
  Setpoint sp;
  sp.mode = mode;
  sp.alpha = alpha;
  const Status status = check(sp);
  if (status != Status::ok) return status;
  if (!q_dot.allFinite()) return Status::non_finite_input;
  Matrix92 H, dH;
  kinematics(mode, alpha, H, dH);
  if (dof(mode) == 2) {
    const Eigen::Matrix2d HtH = H.transpose() * H;  // positive definite: the columns of H_k are independent
    s_dot = HtH.inverse() * (H.transpose() * q_dot);
  } else {
    s_dot[0] = H.col(0).dot(q_dot) / H.col(0).squaredNorm();
  }
  return Status::ok;
}

}  // namespace agvdyn::ff
