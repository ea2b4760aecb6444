// Properties of the feed-forward that do not need the Python reference: rolling constraints
// (A q_dot = 0 with an independent A(alpha), eq. 1-2), the distribution on the admissible space
// (null space of A by LU), the lateral stops, no heap allocation, error codes.
#include <agvdyn_ff/feedforward.hpp>

#include <Eigen/LU>
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <new>
#include <random>

namespace ff = agvdyn::ff;

// --- allocation counter: every operator new of the test binary ------------------------------------
namespace {
std::atomic<long> g_allocations{0};
}
void* operator new(std::size_t n) {
  ++g_allocations;
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) {
  ++g_allocations;
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
long agvdyn_ff_test_allocations() { return g_allocations.load(); }  // also for test_tracker.cpp
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

namespace {

constexpr double kPi = 3.14159265358979323846;
using Matrix89 = Eigen::Matrix<double, 8, 9>;

// A(alpha) of eq. (1)-(2), written from PLATFORM.md (lateral rows 0-3, longitudinal rows 4-7).
Matrix89 constraint_matrix(const ff::Geometry& g, const ff::Vector2& alpha) {
  Matrix89 A = Matrix89::Zero();
  const double cx[4] = {g.l / 2, -g.l / 2, g.l / 2, -g.l / 2};
  const double cy[4] = {g.b / 2, g.b / 2, -g.b / 2, -g.b / 2};
  const double side[4] = {1, 1, -1, -1};
  const double mirror[4] = {1, -1, 1, -1};
  for (int i = 0; i < 4; ++i) {
    const int s = i < 2 ? 0 : 1;
    const double theta = mirror[i] * alpha[s];
    const double c = std::cos(theta), sn = std::sin(theta);
    // lateral: e_lat . (v + omega z x c_i); z x c = (-cy, cx)
    A(i, 0) = -sn;
    A(i, 1) = c;
    A(i, 2) = -sn * -cy[i] + c * cx[i];
    // longitudinal: e_long . (v + omega z x c_i) - s_i a (omega + theta_dot) - r beta_dot
    A(4 + i, 0) = c;
    A(4 + i, 1) = sn;
    A(4 + i, 2) = c * -cy[i] + sn * cx[i] - side[i] * g.a;
    A(4 + i, 3 + s) = -side[i] * g.a * mirror[i];
    A(4 + i, 5 + i) = -g.r;
  }
  return A;
}

ff::Vector9 forces(const ff::Parameters& P, const ff::JointMotion& jm, double eps) {
  const ff::Vector9& qd = jm.q_dot;
  const ff::Vector9& qdd = jm.q_ddot;
  ff::Vector9 f;
  f << P.m_ch * (qdd[0] - qd[1] * qd[2]), P.m_ch * (qdd[1] + qd[0] * qd[2]), (P.C_l + P.C_r + P.C_ch) * qdd[2],
      P.C_l * qdd[3] + P.d_vl * qd[3] + P.d_cl * std::tanh(qd[3] / eps),
      P.C_r * qdd[4] + P.d_vr * qd[4] + P.d_cr * std::tanh(qd[4] / eps), 0, 0, 0, 0;
  for (int i = 5; i < 9; ++i) f[i] = P.B_w * qdd[i] + P.d_vw * qd[i] + P.d_cw * std::tanh(qd[i] / eps);
  return f;
}

ff::Vector9 input(const ff::Geometry& g, const ff::Vector4& u) {
  ff::Vector9 Bu = ff::Vector9::Zero();
  Bu.tail<4>() = g.i_G * u;
  return Bu;
}

ff::Vector2 car_like_alpha(const ff::Geometry& g, double av) {
  const double k = g.b / g.l, s = std::sin(av), c = std::cos(av);
  return {std::atan2(s, c - k * s), std::atan2(s, c + k * s)};
}

ff::Vector2 nominal(const ff::Geometry& g, ff::Mode mode) {
  const double rot = std::atan2(g.l, g.b);
  switch (mode) {
    case ff::Mode::lateral: return {-kPi / 2, kPi / 2};
    case ff::Mode::rotation: return {-rot, rot};
    default: return {0, 0};
  }
}

struct Fixture : ::testing::Test {
  ff::Geometry g{};
  ff::Parameters p = ff::Parameters::paper();
  ff::Model model;
  std::mt19937_64 rng{7};
  std::uniform_real_distribution<double> unit{-1.0, 1.0};
  void SetUp() override { ASSERT_EQ(ff::Model::create(g, p, ff::Settings{}, &model), ff::Status::ok); }

  ff::Setpoint random(ff::Mode mode) {
    ff::Setpoint sp;
    sp.mode = mode;
    if (mode == ff::Mode::parking) {
      sp.alpha = ff::Vector2(unit(rng), unit(rng)) * 1.5;
    } else if (mode == ff::Mode::car_like) {
      sp.alpha = car_like_alpha(g, 0.95 * std::atan2(g.l, g.b) * unit(rng));
    } else {
      sp.alpha = nominal(g, mode);
    }
    sp.s_dot = ff::Vector2(unit(rng), unit(rng));
    sp.s_ddot = ff::Vector2(unit(rng), unit(rng)) * 2;
    if (ff::dof(mode) == 1) sp.s_dot[1] = sp.s_ddot[1] = 0;
    return sp;
  }
};

const ff::Mode kModes[] = {ff::Mode::parking, ff::Mode::car_like, ff::Mode::lateral, ff::Mode::rotation,
                           ff::Mode::straight};

}  // namespace

TEST(Labels, RoundTripAndPythonSpellings) {
  for (ff::Mode m : kModes) {
    ff::Mode back;
    ASSERT_TRUE(ff::mode_from_label(ff::label(m), &back));
    EXPECT_EQ(back, m);
  }
  ff::Mode m;
  EXPECT_TRUE(ff::mode_from_label(" Straight ", &m));
  EXPECT_EQ(m, ff::Mode::straight);
  EXPECT_TRUE(ff::mode_from_label("car-like", &m));
  EXPECT_EQ(m, ff::Mode::car_like);
  EXPECT_FALSE(ff::mode_from_label("6", &m));
  EXPECT_FALSE(ff::mode_from_label("", &m));
  EXPECT_FALSE(ff::mode_from_label(nullptr, &m));
  EXPECT_STREQ(ff::label(static_cast<ff::Mode>(9)), "?");
}

TEST(Model, RefusesGeometryParametersAndSettingsThatBreakTheirInvariants) {
  ff::Model m;
  const ff::Parameters p = ff::Parameters::paper();
  EXPECT_EQ(ff::Model::create(ff::Geometry{}, p, ff::Settings{}, &m), ff::Status::ok);
  EXPECT_EQ(ff::Model::create(ff::Geometry{1.2, 0.8, 0.4, 0.1, 25}, p, ff::Settings{}, &m), ff::Status::invalid_model);
  EXPECT_EQ(ff::Model::create(ff::Geometry{0, 0.8, 0.05, 0.1, 25}, p, ff::Settings{}, &m), ff::Status::invalid_model);
  EXPECT_EQ(ff::Model::create(ff::Geometry{1.2, 0.8, 0.05, -0.1, 25}, p, ff::Settings{}, &m), ff::Status::invalid_model);
  ff::Parameters bad = p;
  bad.m_ch = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(ff::Model::create(ff::Geometry{}, bad, ff::Settings{}, &m), ff::Status::invalid_model);
  ff::Settings s;
  s.epsilon = 0;
  EXPECT_EQ(ff::Model::create(ff::Geometry{}, p, s, &m), ff::Status::invalid_model);
  EXPECT_EQ(ff::Model::create(ff::Geometry{}, p, ff::Settings{}, nullptr), ff::Status::invalid_model);
}

TEST_F(Fixture, JointMotionSatisfiesTheRollingConstraints) {
  for (ff::Mode mode : kModes) {
    for (int trial = 0; trial < 50; ++trial) {
      const ff::Setpoint sp = random(mode);
      ff::JointMotion jm;
      ASSERT_EQ(model.joint_motion(sp, jm), ff::Status::ok);
      const double residual = (constraint_matrix(g, sp.alpha) * jm.q_dot).cwiseAbs().maxCoeff();
      EXPECT_LT(residual, 1e-12 * (1 + jm.q_dot.cwiseAbs().maxCoeff())) << "mode " << ff::label(mode);
    }
  }
}

TEST_F(Fixture, CarLikeAccelerationIsTheDerivativeOfTheVelocity) {
  // q_ddot of eq. (20) against a central difference of q_dot along the motion (mode 2)
  const double h = 1e-6;
  for (int trial = 0; trial < 20; ++trial) {
    const double av = 0.8 * unit(rng), x = unit(rng);
    const ff::Vector2 sd(unit(rng), unit(rng)), sdd(unit(rng), unit(rng));
    auto at = [&](double dt) {
      ff::Setpoint sp;
      sp.mode = ff::Mode::car_like;
      sp.alpha = car_like_alpha(g, av + sd[0] * dt + 0.5 * sdd[0] * dt * dt);
      sp.s_dot = sd + sdd * dt;
      sp.s_ddot = sdd;
      ff::JointMotion jm;
      EXPECT_EQ(model.joint_motion(sp, jm), ff::Status::ok);
      return jm;
    };
    (void)x;
    const ff::Vector9 numeric = (at(h).q_dot - at(-h).q_dot) / (2 * h);
    const ff::Vector9 analytic = at(0).q_ddot;
    EXPECT_LT((numeric - analytic).cwiseAbs().maxCoeff(), 1e-6 * (1 + analytic.cwiseAbs().maxCoeff()));
  }
}

TEST_F(Fixture, NoNetForceOnAnyAdmissibleDirection) {
  // modes 1, 2, 4, straight: N^T (B u - Theta p) = 0 for N = the whole null space of A(alpha)
  for (ff::Mode mode : {ff::Mode::parking, ff::Mode::car_like, ff::Mode::rotation, ff::Mode::straight}) {
    for (int trial = 0; trial < 30; ++trial) {
      const ff::Setpoint sp = random(mode);
      ff::Vector4 u;
      ff::JointMotion jm;
      ASSERT_EQ(model.feedforward(sp, u, &jm), ff::Status::ok);
      const Eigen::MatrixXd N = Eigen::FullPivLU<Eigen::MatrixXd>(constraint_matrix(g, sp.alpha)).kernel();
      ASSERT_EQ(N.cols(), mode == ff::Mode::parking ? 2 : 3) << "mode " << ff::label(mode);
      const ff::Vector9 f = forces(p, jm, 0.01);
      const Eigen::VectorXd net = N.transpose() * (input(g, u) - f);
      EXPECT_LT(net.cwiseAbs().maxCoeff(), 1e-9 * (1 + (N.transpose() * f).cwiseAbs().maxCoeff()))
          << "mode " << ff::label(mode);
    }
  }
}

TEST_F(Fixture, MinimumNormAmongTheSolutions) {
  // u is orthogonal to the null space of N^T B (mode 2): adding a null direction only grows it
  for (int trial = 0; trial < 20; ++trial) {
    const ff::Setpoint sp = random(ff::Mode::car_like);
    ff::Vector4 u;
    ASSERT_EQ(model.feedforward(sp, u), ff::Status::ok);
    const Eigen::MatrixXd N = Eigen::FullPivLU<Eigen::MatrixXd>(constraint_matrix(g, sp.alpha)).kernel();
    const Eigen::MatrixXd M = g.i_G * N.bottomRows(4).transpose();  // 3 x 4
    const Eigen::MatrixXd Z = Eigen::FullPivLU<Eigen::MatrixXd>(M).kernel();
    ASSERT_EQ(Z.cols(), 1);
    EXPECT_LT(std::abs(Z.col(0).normalized().dot(u)), 1e-9 * (1 + u.norm()));
  }
}

TEST_F(Fixture, LateralModePressesEachSteeringIntoItsStop) {
  for (int trial = 0; trial < 100; ++trial) {
    const ff::Setpoint sp = random(ff::Mode::lateral);
    ff::Vector4 u;
    ff::JointMotion jm;
    ASSERT_EQ(model.feedforward(sp, u, &jm), ff::Status::ok);
    const ff::Vector9 net = input(g, u) - forces(p, jm, 0.01);
    // net generalized force on steering either side at rest (columns of H_1) and on v_y
    ff::JointMotion probe;
    ff::Setpoint steer;
    steer.mode = ff::Mode::parking;
    steer.alpha = sp.alpha;
    double on_steering[2];
    for (int j = 0; j < 2; ++j) {
      steer.s_dot = ff::Vector2::Unit(j);
      ASSERT_EQ(model.joint_motion(steer, probe), ff::Status::ok);
      on_steering[j] = probe.q_dot.dot(net);
    }
    const double scale = 1e-9 * (1 + 1e3 * u.cwiseAbs().maxCoeff());
    EXPECT_LE(on_steering[0], scale) << "left steering pulled off its stop at -pi/2";
    EXPECT_GE(on_steering[1], -scale) << "right steering pulled off its stop at +pi/2";
    EXPECT_NEAR(jm.q_dot.dot(net) / (sp.s_dot[0] == 0 ? 1 : sp.s_dot[0]), 0.0, scale) << "lateral force not balanced";
  }
}

TEST_F(Fixture, PerStepCallDoesNotAllocate) {
  ff::Setpoint inputs[5];
  for (int k = 0; k < 5; ++k) inputs[k] = random(kModes[k]);
  ff::Setpoint bad = inputs[2];
  bad.alpha = ff::Vector2(0.1, 0.2);
  ff::Vector4 u;
  ff::JointMotion jm;
  ff::Vector2 s;
  const long before = g_allocations.load();
  for (int rep = 0; rep < 100; ++rep) {
    for (const ff::Setpoint& sp : inputs) {
      (void)model.feedforward(sp, u, &jm);
      (void)model.joint_motion(sp, jm);
      (void)model.generalized_velocities(sp.mode, sp.alpha, jm.q_dot, s);
    }
    (void)model.feedforward(bad, u);
  }
  EXPECT_EQ(g_allocations.load() - before, 0);
}

TEST_F(Fixture, ErrorCodesInsteadOfExceptions) {
  ff::Setpoint sp = random(ff::Mode::car_like);
  ff::Vector4 u;
  ff::JointMotion jm;
  sp.mode = static_cast<ff::Mode>(0);
  EXPECT_EQ(model.feedforward(sp, u, &jm), ff::Status::unknown_mode);
  sp.mode = static_cast<ff::Mode>(6);
  EXPECT_EQ(model.feedforward(sp, u), ff::Status::unknown_mode);
  sp = random(ff::Mode::straight);
  sp.s_ddot[0] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(model.feedforward(sp, u, &jm), ff::Status::non_finite_input);
  EXPECT_TRUE(u.isZero(0));
  EXPECT_TRUE(jm.q_dot.isZero(0));
  sp.s_ddot[1] = std::numeric_limits<double>::quiet_NaN();  // unused second entry of a 1-dof mode
  sp.s_ddot[0] = 0.3;
  EXPECT_EQ(model.feedforward(sp, u), ff::Status::ok);
  sp = random(ff::Mode::rotation);
  sp.alpha[1] += 0.021;
  EXPECT_EQ(model.feedforward(sp, u), ff::Status::not_in_mode);
  sp.alpha[1] -= 0.002;  // 0.019 rad off: within the tolerance
  EXPECT_EQ(model.feedforward(sp, u), ff::Status::ok);
  sp = random(ff::Mode::parking);
  sp.alpha[0] = kPi / 2 + 1e-3;
  EXPECT_EQ(model.feedforward(sp, u), ff::Status::beyond_stop);
  sp.alpha[0] = kPi / 2 + 1e-7;  // encoder round-off beyond the stop
  EXPECT_EQ(model.feedforward(sp, u), ff::Status::ok);
  EXPECT_STREQ(ff::to_string(ff::Status::not_in_mode), "not_in_mode");
}

TEST(Model, WithoutContactOffsetTheWheelsCannotSteer) {
  ff::Model m;
  ASSERT_EQ(ff::Model::create(ff::Geometry{1.2, 0.8, 0.0, 0.1, 25}, ff::Parameters::paper(), ff::Settings{}, &m),
            ff::Status::ok);
  ff::Setpoint sp;
  sp.mode = ff::Mode::parking;
  sp.s_dot = ff::Vector2(0.2, 0.1);
  ff::Vector4 u;
  EXPECT_EQ(m.feedforward(sp, u), ff::Status::singular);
  sp.mode = ff::Mode::lateral;
  sp.alpha = ff::Vector2(-kPi / 2, kPi / 2);
  EXPECT_EQ(m.feedforward(sp, u), ff::Status::ok);  // pseudoinverse, as in Python
}

TEST_F(Fixture, GeneralizedVelocitiesInvertTheKinematicModel) {
  for (ff::Mode mode : kModes) {
    for (int trial = 0; trial < 20; ++trial) {
      const ff::Setpoint sp = random(mode);
      ff::JointMotion jm;
      ASSERT_EQ(model.joint_motion(sp, jm), ff::Status::ok);
      ff::Vector2 s;
      ASSERT_EQ(model.generalized_velocities(mode, sp.alpha, jm.q_dot, s), ff::Status::ok);
      EXPECT_LT((s - sp.s_dot).cwiseAbs().maxCoeff(), 1e-12) << "mode " << ff::label(mode);
    }
  }
}

// --- the model beyond the paper (issue 30): Stribeck friction per joint group, off-centre chassis ------
namespace {

// The extension's forces written out from agvdyn.model_spec (independently of the library's code).
ff::Vector9 extended_forces(const ff::Parameters& P, const ff::Extension& e, const ff::JointMotion& jm, double eps) {
  ff::Vector9 f = forces(P, jm, eps);
  const ff::Vector9& qd = jm.q_dot;
  const ff::Vector9& qdd = jm.q_ddot;
  if (e.stribeck) {
    const double d_c[3] = {P.d_cl, P.d_cr, P.d_cw};
    for (int i = 3; i < 9; ++i) {
      const int g = i == 3 ? 0 : i == 4 ? 1 : 2;
      f[i] += (e.d_s[g] - d_c[g]) * std::exp(-std::pow(qd[i] / e.w_s[g], 2)) * std::tanh(qd[i] / eps);
    }
  }
  if (e.com_offset) {
    // Newton-Euler about the reference point: the centre of mass accelerates with
    // a + w_dot z x r_c - w^2 r_c; the moment of m a_com about the reference point adds r_c x m a_com
    const double w = qd[2], w_dot = qdd[2];
    const double ax = qdd[0] - qd[1] * w, ay = qdd[1] + qd[0] * w;
    const double acx = ax - w_dot * e.y_c - w * w * e.x_c, acy = ay + w_dot * e.x_c - w * w * e.y_c;
    f[0] = P.m_ch * acx;
    f[1] = P.m_ch * acy;
    // C_ch is about the reference point: C_com = C_ch - m |r_c|^2
    const double c_com = P.C_ch - P.m_ch * (e.x_c * e.x_c + e.y_c * e.y_c);
    f[2] = (c_com + P.C_l + P.C_r) * w_dot + P.m_ch * (e.x_c * acy - e.y_c * acx);
  }
  return f;
}

ff::Extension breakaway_and_offset() {
  ff::Extension e;
  e.stribeck = true;
  e.d_s = {17.0, 21.0, 5.1};
  e.w_s = {0.05, 0.1, 0.02};
  e.com_offset = true;
  e.x_c = 0.15;
  e.y_c = -0.1;
  e.delay_s = 0.006;
  return e;
}

}  // namespace

TEST_F(Fixture, ExtendedModelHasNoNetForceOnAnyAdmissibleDirection) {
  ff::Model extended;
  const ff::Extension e = breakaway_and_offset();
  ASSERT_EQ(model.with_extension(e, &extended), ff::Status::ok);
  for (ff::Mode mode : {ff::Mode::parking, ff::Mode::car_like, ff::Mode::rotation, ff::Mode::straight}) {
    double changed = 0;
    for (int trial = 0; trial < 30; ++trial) {
      ff::Setpoint sp = random(mode);
      sp.s_dot *= std::pow(10.0, -2.0 * std::abs(unit(rng)));  // through the Stribeck range
      ff::Vector4 u, u_paper;
      ff::JointMotion jm;
      ASSERT_EQ(extended.feedforward(sp, u, &jm), ff::Status::ok);
      ASSERT_EQ(model.feedforward(sp, u_paper), ff::Status::ok);
      const Eigen::MatrixXd N = Eigen::FullPivLU<Eigen::MatrixXd>(constraint_matrix(g, sp.alpha)).kernel();
      const ff::Vector9 f = extended_forces(p, e, jm, 0.01);
      const Eigen::VectorXd net = N.transpose() * (input(g, u) - f);
      EXPECT_LT(net.cwiseAbs().maxCoeff(), 1e-9 * (1 + (N.transpose() * f).cwiseAbs().maxCoeff()))
          << "mode " << ff::label(mode);
      changed = std::max(changed, (u - u_paper).cwiseAbs().maxCoeff() / (1e-3 + u_paper.cwiseAbs().maxCoeff()));
    }
    // pure rotation about the reference point and straight motion: the wheels' lateral constraint
    // forces take the offset's chassis forces; only the wheels' breakaway below w_sw is left
    if (mode == ff::Mode::parking || mode == ff::Mode::car_like) EXPECT_GT(changed, 1e-3) << "mode " << ff::label(mode);
  }
}

TEST_F(Fixture, EqualBreakawayAndCoulombLevelsAndNoOffsetAreThePaperModel) {
  ff::Extension e;
  e.stribeck = true;
  e.d_s = {p.d_cl, p.d_cr, p.d_cw};
  e.w_s = {0.05, 0.01, 0.3};
  e.com_offset = true;  // at the reference point
  ff::Model extended;
  ASSERT_EQ(ff::Model::create(g, p, e, ff::Settings{}, &extended), ff::Status::ok);
  for (ff::Mode mode : kModes) {
    for (int trial = 0; trial < 20; ++trial) {
      ff::Setpoint sp = random(mode);
      sp.s_dot *= std::pow(10.0, -2.0 * std::abs(unit(rng)));
      ff::Vector4 u, u_paper;
      ASSERT_EQ(extended.feedforward(sp, u), ff::Status::ok);
      ASSERT_EQ(model.feedforward(sp, u_paper), ff::Status::ok);
      EXPECT_TRUE(u == u_paper) << "mode " << ff::label(mode) << ": " << (u - u_paper).transpose();
    }
  }
}

TEST_F(Fixture, ExtendedModelDoesNotAllocateAndKeepsItsExtension) {
  ff::Model extended;
  ASSERT_EQ(model.with_extension(breakaway_and_offset(), &extended), ff::Status::ok);
  ff::Parameters heavier = p;
  heavier.m_ch += 300;
  ASSERT_EQ(extended.with_parameters(heavier, &extended), ff::Status::ok);
  EXPECT_TRUE(extended.extension().stribeck && extended.extension().com_offset);
  EXPECT_DOUBLE_EQ(extended.extension().delay_s, 0.006);
  ff::Setpoint inputs[5];
  for (int k = 0; k < 5; ++k) inputs[k] = random(kModes[k]);
  ff::Vector4 u;
  ff::JointMotion jm;
  const long before = g_allocations.load();
  for (int rep = 0; rep < 100; ++rep) {
    for (const ff::Setpoint& sp : inputs) (void)extended.feedforward(sp, u, &jm);
  }
  EXPECT_EQ(g_allocations.load() - before, 0);
}

TEST(Model, RefusesAnExtensionThatBreaksItsInvariants) {
  ff::Model m;
  const ff::Parameters p = ff::Parameters::paper();
  ff::Extension e;
  e.stribeck = true;
  e.w_s = {0.05, 0.0, 0.1};
  EXPECT_EQ(ff::Model::create(ff::Geometry{}, p, e, ff::Settings{}, &m), ff::Status::invalid_model);
  e.stribeck = false;  // w_s unused without breakaway friction
  EXPECT_EQ(ff::Model::create(ff::Geometry{}, p, e, ff::Settings{}, &m), ff::Status::ok);
  e.x_c = std::numeric_limits<double>::infinity();
  EXPECT_EQ(ff::Model::create(ff::Geometry{}, p, e, ff::Settings{}, &m), ff::Status::invalid_model);
  EXPECT_EQ(m.with_extension(e, &m), ff::Status::invalid_model);
  EXPECT_FALSE(m.extension().stribeck);  // untouched
}
