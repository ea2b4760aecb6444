// agvdyn.ffcpp._core: the C++ feed-forward (agvdyn_ff) for Python, through nanobind.
// The Python glue (src/agvdyn/ffcpp/__init__.py) checks and shapes the arrays; this layer loops
// over the samples with the GIL released and reports the first failing row.
#include <agvdyn_ff/feedforward.hpp>
#include <agvdyn_ff/parameter_file.hpp>

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include <stdexcept>
#include <string>
#include <tuple>
#include <vector>

namespace nb = nanobind;
namespace ff = agvdyn::ff;

namespace {

using In2 = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Out2 = nb::ndarray<double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;

ff::Model make_model(std::tuple<double, double, double, double, double> geometry,
                     const std::vector<double>& parameters, double epsilon, double mode_tolerance,
                     double stop_tolerance) {
  if (parameters.size() != 11) throw std::invalid_argument("expected 11 parameters in the order of eq. (18)");
  const auto [l, b, a, r, i_G] = geometry;
  ff::Vector11 p;
  for (int k = 0; k < 11; ++k) p[k] = parameters[static_cast<std::size_t>(k)];
  ff::Settings settings;
  settings.epsilon = epsilon;
  settings.mode_tolerance = mode_tolerance;
  settings.stop_tolerance = stop_tolerance;
  ff::Model model;
  const ff::Status status = ff::Model::create(ff::Geometry{l, b, a, r, i_G}, ff::Parameters::from_vector(p), settings, &model);
  if (status != ff::Status::ok) {
    throw std::invalid_argument(std::string("agvdyn_ff model: ") + ff::to_string(status) +
                                ": expected l, b, r, i_G > 0, |a| < min(l, b)/2, finite parameters, epsilon > 0");
  }
  return model;
}

void check_shape(const char* name, std::size_t rows, std::size_t cols, std::size_t n, std::size_t width) {
  if (rows != n || cols != width) {
    throw std::invalid_argument(std::string(name) + " of shape (" + std::to_string(rows) + ", " + std::to_string(cols) +
                                "): expected (" + std::to_string(n) + ", " + std::to_string(width) + ")");
  }
}

// u (N, 4) and, when given with N rows, q_dot and q_ddot (N, 9) of N setpoints in one mode.
// Returns (status code, first failing row or -1); rows after a failure are still computed.
std::tuple<int, long> feedforward(const ff::Model& model, int mode_value, In2 alpha, In2 s_dot, In2 s_ddot, Out2 u,
                                  Out2 q_dot, Out2 q_ddot) {
  const ff::Mode mode = static_cast<ff::Mode>(mode_value);
  if (mode_value < 1 || mode_value > 5) throw std::invalid_argument("mode: expected 1, 2, 3, 4 or 5 (straight)");
  const std::size_t n = alpha.shape(0);
  const std::size_t k = static_cast<std::size_t>(ff::dof(mode));
  check_shape("alpha", alpha.shape(0), alpha.shape(1), n, 2);
  check_shape("s_dot", s_dot.shape(0), s_dot.shape(1), n, k);
  check_shape("s_ddot", s_ddot.shape(0), s_ddot.shape(1), n, k);
  check_shape("u", u.shape(0), u.shape(1), n, 4);
  const bool motion = q_dot.shape(0) == n && n > 0;
  if (motion) {
    check_shape("q_dot", q_dot.shape(0), q_dot.shape(1), n, 9);
    check_shape("q_ddot", q_ddot.shape(0), q_ddot.shape(1), n, 9);
  }
  const double* a = alpha.data();
  const double* sd = s_dot.data();
  const double* sdd = s_ddot.data();
  double* out = u.data();
  double* qd = motion ? q_dot.data() : nullptr;
  double* qdd = motion ? q_ddot.data() : nullptr;
  int first_status = 0;
  long first_row = -1;
  {
    nb::gil_scoped_release release;
    ff::Setpoint sp;
    sp.mode = mode;
    ff::Vector4 torque;
    ff::JointMotion jm;
    for (std::size_t j = 0; j < n; ++j) {
      sp.alpha = ff::Vector2(a[2 * j], a[2 * j + 1]);
      for (std::size_t c = 0; c < k; ++c) {
        sp.s_dot[c] = sd[k * j + c];
        sp.s_ddot[c] = sdd[k * j + c];
      }
      const ff::Status status = model.feedforward(sp, torque, &jm);
      if (status != ff::Status::ok && first_row < 0) {
        first_status = static_cast<int>(status);
        first_row = static_cast<long>(j);
      }
      for (int c = 0; c < 4; ++c) out[4 * j + c] = torque[c];
      if (motion) {
        for (int c = 0; c < 9; ++c) {
          qd[9 * j + c] = jm.q_dot[c];
          qdd[9 * j + c] = jm.q_ddot[c];
        }
      }
    }
  }
  return {first_status, first_row};
}

nb::dict parameter_file(const std::string& path) {
  ff::ParameterFile file;
  std::string error;
  if (!ff::read_parameter_file(path, &file, &error)) throw std::invalid_argument(error);
  nb::dict parameters;
  const ff::Vector11 p = file.parameters.to_vector();
  for (int k = 0; k < 11; ++k) parameters[ff::Parameters::names[k]] = p[k];
  nb::dict out;
  out["parameters"] = parameters;
  if (file.has_platform) {
    nb::dict g;
    g["name"] = file.platform_name;
    g["l"] = file.platform.l;
    g["b"] = file.platform.b;
    g["a"] = file.platform.a;
    g["r"] = file.platform.r;
    g["i_G"] = file.platform.i_G;
    out["platform"] = g;
  } else {
    out["platform"] = nb::none();
  }
  return out;
}

}  // namespace

NB_MODULE(_core, m) {
  m.doc() = "C++ feed-forward of eq. (21) (library agvdyn_ff, cpp/); use it through agvdyn.ffcpp.";
  nb::class_<ff::Model>(m, "Model")
      .def(
          "__init__",
          [](ff::Model* self, std::tuple<double, double, double, double, double> geometry,
             const std::vector<double>& parameters, double epsilon, double mode_tolerance, double stop_tolerance) {
            new (self) ff::Model(make_model(geometry, parameters, epsilon, mode_tolerance, stop_tolerance));
          },
          nb::arg("geometry"), nb::arg("parameters"), nb::arg("epsilon"),
           nb::arg("mode_tolerance"), nb::arg("stop_tolerance"),
           "Model((l, b, a, r, i_G), parameters[11], epsilon, mode_tolerance, stop_tolerance)")
      .def("feedforward", &feedforward, nb::arg("mode"), nb::arg("alpha"), nb::arg("s_dot"), nb::arg("s_ddot"),
           nb::arg("u"), nb::arg("q_dot"), nb::arg("q_ddot"),
           "Fill u (N, 4) (and q_dot, q_ddot (N, 9) when they have N rows); return (status, first failing row or -1).");
  m.def("status_name", [](int code) { return std::string(ff::to_string(static_cast<ff::Status>(code))); });
  m.def("read_parameter_file", &parameter_file, nb::arg("path"),
        "The C++ reader of parameter files: {'parameters': {name: value}, 'platform': {...} or None}.");
}
