// The shared test vectors (vectors.json, written by make_vectors.py from the Python reference):
// every valid case to 1e-9 relative, every invalid case with its status.
#include <agvdyn_ff/feedforward.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "document.hpp"

namespace ff = agvdyn::ff;
using agvdyn::ff::detail::Node;

namespace {

struct Vectors {
  Node root;
  std::vector<ff::Model> models;
  std::vector<ff::Model> extended;  // the models beyond the paper (issue 30) on those vehicles
  double relative = 0, absolute = 0;
};

double number(const Node& node) {
  double v = 0;
  EXPECT_TRUE(node.number(&v)) << "not a number at line " << node.line << ": " << node.text;
  return v;
}

template <int N>
Eigen::Matrix<double, N, 1> vector_of(const Node& node, int size = N) {
  Eigen::Matrix<double, N, 1> v = Eigen::Matrix<double, N, 1>::Zero();
  EXPECT_TRUE(node.is_sequence());
  EXPECT_EQ(static_cast<int>(node.values.size()), size) << "line " << node.line;
  for (int k = 0; k < size && k < static_cast<int>(node.values.size()); ++k) v[k] = number(node.values[k]);
  return v;
}

const Vectors& vectors() {
  static Vectors v = [] {
    Vectors out;
    std::string error;
    const std::string path = std::string(AGVDYN_FF_TEST_DATA) + "/vectors.json";
    if (!agvdyn::ff::detail::read_document(path, &out.root, &error)) {
      ADD_FAILURE() << error;
      return out;
    }
    const Node& tol = *out.root.find("tolerance");
    out.relative = number(*tol.find("relative"));
    out.absolute = number(*tol.find("absolute"));
    const Node& s = *out.root.find("settings");
    ff::Settings settings;
    settings.epsilon = number(*s.find("epsilon"));
    settings.mode_tolerance = number(*s.find("mode_tolerance"));
    settings.stop_tolerance = number(*s.find("stop_tolerance"));
    for (const Node& m : out.root.find("models")->values) {
      const Node& g = *m.find("geometry");
      const ff::Geometry geometry{number(*g.find("l")), number(*g.find("b")), number(*g.find("a")),
                                  number(*g.find("r")), number(*g.find("i_G"))};
      ff::Vector11 p;
      for (int k = 0; k < 11; ++k) p[k] = number(*m.find("parameters")->find(ff::Parameters::names[k]));
      ff::Model model;
      EXPECT_EQ(ff::Model::create(geometry, ff::Parameters::from_vector(p), settings, &model), ff::Status::ok);
      out.models.push_back(model);
    }
    for (const Node& m : out.root.find("extended_models")->values) {
      const Node& spec = *m.find("model");
      const Node& extra = *m.find("extra");
      ff::Extension e;
      e.stribeck = spec.find("friction")->text == "stribeck";
      e.com_offset = spec.find("com_offset")->text == "true";
      e.delay_s = number(*spec.find("delay_s"));
      double* slots[8] = {&e.d_s[0], &e.d_s[1], &e.d_s[2], &e.w_s[0], &e.w_s[1], &e.w_s[2], &e.x_c, &e.y_c};
      for (std::size_t k = 0; k < 8; ++k) {
        if (const Node* value = extra.find(ff::Extension::names[k]); value != nullptr) *slots[k] = number(*value);
      }
      ff::Model model;
      const auto vehicle = static_cast<std::size_t>(number(*m.find("vehicle")));
      EXPECT_EQ(out.models.at(vehicle).with_extension(e, &model), ff::Status::ok);
      out.extended.push_back(model);
    }
    return out;
  }();
  return v;
}

ff::Setpoint setpoint_of(const Node& c) {
  ff::Setpoint sp;
  EXPECT_TRUE(ff::mode_from_label(c.find("mode")->text.c_str(), &sp.mode)) << c.find("mode")->text;
  const int n = ff::dof(sp.mode);
  sp.alpha = vector_of<2>(*c.find("alpha"));
  sp.s_dot = vector_of<2>(*c.find("s_dot"), n);
  sp.s_ddot = vector_of<2>(*c.find("s_ddot"), n);
  return sp;
}

template <typename V>
double bound(const V& reference, const Vectors& v) {
  return v.relative * reference.cwiseAbs().maxCoeff() + v.absolute;
}

}  // namespace

TEST(Vectors, FileHasCasesForEveryModeAndVehicle) {
  const Vectors& v = vectors();
  ASSERT_EQ(v.models.size(), 3u);
  int per_mode[6] = {0, 0, 0, 0, 0, 0};
  for (const Node& c : v.root.find("cases")->values) ++per_mode[static_cast<int>(setpoint_of(c).mode)];
  for (int m = 1; m <= 5; ++m) EXPECT_GE(per_mode[m], 30) << "mode " << m;
  EXPECT_GE(v.root.find("invalid")->values.size(), 10u);
}

TEST(Vectors, TorquesAndJointMotionEqualThePythonReference) {
  const Vectors& v = vectors();
  double worst = 0;
  int checked = 0;
  for (const Node& c : v.root.find("cases")->values) {
    const ff::Model& model = v.models.at(static_cast<std::size_t>(number(*c.find("model"))));
    const ff::Setpoint sp = setpoint_of(c);
    const ff::Vector4 u_ref = vector_of<4>(*c.find("u"));
    const ff::Vector9 qd_ref = vector_of<9>(*c.find("q_dot"));
    const ff::Vector9 qdd_ref = vector_of<9>(*c.find("q_ddot"));
    ff::Vector4 u;
    ff::JointMotion jm;
    ASSERT_EQ(model.feedforward(sp, u, &jm), ff::Status::ok) << "line " << c.line;
    EXPECT_LE((u - u_ref).cwiseAbs().maxCoeff(), bound(u_ref, v))
        << "line " << c.line << " mode " << ff::label(sp.mode) << "\n u     " << u.transpose() << "\n u_ref " << u_ref.transpose();
    EXPECT_LE((jm.q_dot - qd_ref).cwiseAbs().maxCoeff(), bound(qd_ref, v)) << "line " << c.line;
    EXPECT_LE((jm.q_ddot - qdd_ref).cwiseAbs().maxCoeff(), bound(qdd_ref, v)) << "line " << c.line;
    const double scale = u_ref.cwiseAbs().maxCoeff();
    if (scale > 0) worst = std::max(worst, (u - u_ref).cwiseAbs().maxCoeff() / scale);
    ++checked;
  }
  EXPECT_GE(checked, 200);
  RecordProperty("max_relative_deviation", std::to_string(worst));
  std::printf("[ vectors  ] %d cases, largest deviation %.3g of the largest torque\n", checked, worst);
}

TEST(Vectors, ExtendedModelTorquesEqualThePythonReference) {
  // Stribeck friction per joint group, an off-centre centre of mass, a delay (carried, not applied)
  const Vectors& v = vectors();
  ASSERT_GE(v.extended.size(), 4u);
  double worst = 0;
  int checked = 0;
  for (const Node& c : v.root.find("extended_cases")->values) {
    const ff::Model& model = v.extended.at(static_cast<std::size_t>(number(*c.find("model"))));
    const ff::Setpoint sp = setpoint_of(c);
    const ff::Vector4 u_ref = vector_of<4>(*c.find("u"));
    ff::Vector4 u;
    ff::JointMotion jm;
    ASSERT_EQ(model.feedforward(sp, u, &jm), ff::Status::ok) << "line " << c.line;
    EXPECT_LE((u - u_ref).cwiseAbs().maxCoeff(), bound(u_ref, v))
        << "line " << c.line << " mode " << ff::label(sp.mode) << "\n u     " << u.transpose() << "\n u_ref " << u_ref.transpose();
    EXPECT_LE((jm.q_ddot - vector_of<9>(*c.find("q_ddot"))).cwiseAbs().maxCoeff(), bound(vector_of<9>(*c.find("q_ddot")), v));
    const double scale = u_ref.cwiseAbs().maxCoeff();
    if (scale > 0) worst = std::max(worst, (u - u_ref).cwiseAbs().maxCoeff() / scale);
    ++checked;
  }
  EXPECT_GE(checked, 200);
  std::printf("[ vectors  ] %d extended-model cases, largest deviation %.3g of the largest torque\n", checked, worst);
}

TEST(Vectors, InvalidInputsGiveTheirStatusAndZeroTorques) {
  const Vectors& v = vectors();
  for (const Node& c : v.root.find("invalid")->values) {
    const ff::Model& model = v.models.at(static_cast<std::size_t>(number(*c.find("model"))));
    const ff::Setpoint sp = setpoint_of(c);
    ff::Vector4 u = ff::Vector4::Constant(7.0);
    const ff::Status status = model.feedforward(sp, u);
    EXPECT_STREQ(ff::to_string(status), c.find("status")->text.c_str()) << "line " << c.line;
    EXPECT_TRUE(u.isZero(0)) << "line " << c.line;
  }
}
