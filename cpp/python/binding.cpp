// agvdyn.ffcpp._core: the C++ feed-forward (agvdyn_ff) and payload tracker for Python, through
// nanobind. The Python glue (src/agvdyn/ffcpp/__init__.py) checks and shapes the arrays; this layer
// loops over the samples with the GIL released and reports the first failing row.
#include <agvdyn_ff/feedforward.hpp>
#include <agvdyn_ff/parameter_file.hpp>
#include <agvdyn_ff/tracker.hpp>

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/map.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include <cstdint>
#include <limits>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <tuple>
#include <vector>

namespace nb = nanobind;
namespace ff = agvdyn::ff;

namespace {

using In2 = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Out2 = nb::ndarray<double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;

using Triple = std::tuple<double, double, double>;

// The model beyond the paper (agvdyn.model_spec.ModelParameters) as ff::Extension.
ff::Extension make_extension(bool stribeck, Triple d_s, Triple w_s, bool com_offset, double x_c, double y_c,
                             double delay_s) {
  ff::Extension e;
  e.stribeck = stribeck;
  e.d_s = {std::get<0>(d_s), std::get<1>(d_s), std::get<2>(d_s)};
  e.w_s = {std::get<0>(w_s), std::get<1>(w_s), std::get<2>(w_s)};
  e.com_offset = com_offset;
  e.x_c = x_c;
  e.y_c = y_c;
  e.delay_s = delay_s;
  return e;
}

ff::Model make_model(std::tuple<double, double, double, double, double> geometry,
                     const std::vector<double>& parameters, double epsilon, double mode_tolerance,
                     double stop_tolerance, const ff::Extension& extension) {
  if (parameters.size() != 11) throw std::invalid_argument("expected 11 parameters in the order of eq. (18)");
  const auto [l, b, a, r, i_G] = geometry;
  ff::Vector11 p;
  for (int k = 0; k < 11; ++k) p[k] = parameters[static_cast<std::size_t>(k)];
  ff::Settings settings;
  settings.epsilon = epsilon;
  settings.mode_tolerance = mode_tolerance;
  settings.stop_tolerance = stop_tolerance;
  ff::Model model;
  const ff::Status status = ff::Model::create(ff::Geometry{l, b, a, r, i_G}, ff::Parameters::from_vector(p), extension,
                                              settings, &model);
  if (status != ff::Status::ok) {
    throw std::invalid_argument(std::string("agvdyn_ff model: ") + ff::to_string(status) +
                                ": expected l, b, r, i_G > 0, |a| < min(l, b)/2, finite parameters, epsilon > 0, "
                                "finite extra parameters and Stribeck velocities > 0");
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
  if (file.has_model) {
    const ff::Extension& e = file.extension;
    nb::dict model;
    model["friction"] = e.stribeck ? "stribeck" : "paper";
    model["delay_s"] = e.delay_s;
    model["com_offset"] = e.com_offset;
    out["model"] = model;
    const double values[8] = {e.d_s[0], e.d_s[1], e.d_s[2], e.w_s[0], e.w_s[1], e.w_s[2], e.x_c, e.y_c};
    nb::dict extra;
    for (std::size_t k = 0; k < 8; ++k) {
      if (k < 6 ? e.stribeck : e.com_offset) extra[ff::Extension::names[k]] = values[k];
    }
    out["extra"] = extra;
  } else {
    out["model"] = nb::none();
    out["extra"] = nb::dict();
  }
  return out;
}

// --- payload tracker ------------------------------------------------------------------------------
using Flat = nb::ndarray<double, nb::c_contig, nb::device::cpu>;              // any shape, as a flat buffer
using In1 = nb::ndarray<const double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using InKind = nb::ndarray<const std::int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Out1 = nb::ndarray<double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using OutKind = nb::ndarray<std::int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Event = std::tuple<std::int64_t, std::int64_t, int, int, double, double, double, double>;

ff::PayloadTracker make_tracker(std::tuple<double, double> nominal, std::tuple<double, double> nominal_std, double dt,
                                const std::map<std::string, double>& values, double y_c = 0.0,
                                double y_c_std = std::numeric_limits<double>::infinity()) {
  ff::TrackerSettings s;
  const std::map<std::string, double*> fields = {
      {"change_size", &s.change_size}, {"gate", &s.gate}, {"correlation", &s.correlation},
      {"rotation_correlation", &s.rotation_correlation}, {"threshold", &s.threshold},
      {"random_walk", &s.random_walk}, {"bias_walk", &s.bias_walk}, {"reset_std", &s.reset_std},
      {"noise_time", &s.noise_time}, {"initial_std", &s.initial_std}, {"bias_std", &s.bias_std},
      {"twin_bias_std", &s.twin_bias_std}, {"noise", &s.noise}, {"offset_change", &s.offset_change},
      {"offset_std", &s.offset_std}, {"offset_walk", &s.offset_walk}};
  for (const auto& [key, value] : values) {
    if (key == "warm_rows") {
      s.warm_rows = static_cast<int>(value);
    } else if (key == "com_offset") {
      s.com_offset = value != 0.0;
    } else if (auto it = fields.find(key); it != fields.end()) {
      *it->second = value;
    } else {
      throw std::invalid_argument("tracker setting " + key + ": unknown");
    }
  }
  ff::PayloadTracker tracker;
  const ff::Vector2 n(std::get<0>(nominal), std::get<1>(nominal)), sd(std::get<0>(nominal_std), std::get<1>(nominal_std));
  if (ff::PayloadTracker::create(n, sd, y_c, y_c_std, dt, s, &tracker) != ff::Status::ok) {
    throw std::invalid_argument("agvdyn_ff tracker: invalid_model: expected nominal m_ch, C_ch > 0, stds >= 0, dt > 0, "
                                "every setting finite and > 0 (warm_rows >= 0)");
  }
  return tracker;
}

// The state as the arrays of agvdyn.online.tracker.TrackerState: theta (ns), P (ns, ns), R (4),
// n_rows (20), g (2, 2), Iw (2, 2, ns, ns), bw (2, 2, ns), start (2, 2); CUSUM (i, s) is index 2 i + s;
// ns = 8, 9 with com_offset (tracker.states()).
void check_size(const char* name, std::size_t size, std::size_t expected) {
  if (size != expected) {
    throw std::invalid_argument(std::string(name) + " of " + std::to_string(size) + " values: expected " +
                                std::to_string(expected));
  }
}

void check_state_sizes(std::size_t ns, Flat theta, Flat P, Flat R, Flat n_rows, Flat g, Flat Iw, Flat bw, Flat start) {
  check_size("theta", theta.size(), ns);
  check_size("P", P.size(), ns * ns);
  check_size("R", R.size(), ff::kNoiseClasses);
  check_size("n_rows", n_rows.size(), ff::kTrackerCounts);
  check_size("g", g.size(), 4);
  check_size("Iw", Iw.size(), 4 * ns * ns);
  check_size("bw", bw.size(), 4 * ns);
  check_size("start", start.size(), 4);
}

template <int N>
void load_state_of(ff::PayloadTracker& tracker, ff::TrackerStateOf<N> st, Flat theta, Flat P, Flat R, Flat n_rows,
                   Flat g, Flat Iw, Flat bw, Flat start) {
  check_state_sizes(N, theta, P, R, n_rows, g, Iw, bw, start);
  for (int p = 0; p < N; ++p) {
    st.theta[p] = theta.data()[p];
    for (int q = 0; q < N; ++q) st.P(p, q) = P.data()[N * p + q];
  }
  for (int k = 0; k < ff::kNoiseClasses; ++k) st.R[k] = R.data()[k];
  for (int k = 0; k < ff::kTrackerCounts; ++k) st.n_rows[k] = n_rows.data()[k];
  for (int c = 0; c < 4; ++c) {
    st.g[static_cast<std::size_t>(c)] = g.data()[c];
    st.start[static_cast<std::size_t>(c)] = static_cast<std::int64_t>(start.data()[c]);
    for (int p = 0; p < N; ++p) {
      st.bw[static_cast<std::size_t>(c)][p] = bw.data()[N * c + p];
      for (int q = 0; q < N; ++q) st.Iw[static_cast<std::size_t>(c)](p, q) = Iw.data()[N * N * c + N * p + q];
    }
  }
  st.sample = 0;
  if (tracker.set_state(st) != ff::Status::ok) throw std::invalid_argument("tracker state: NaN or infinity");
}

void load_state(ff::PayloadTracker& tracker, Flat theta, Flat P, Flat R, Flat n_rows, Flat g, Flat Iw, Flat bw, Flat start) {
  if (tracker.states() == ff::kOffsetStates) {
    load_state_of<ff::kOffsetStates>(tracker, tracker.offset_state(), theta, P, R, n_rows, g, Iw, bw, start);
  } else {
    load_state_of<ff::kTrackerStates>(tracker, tracker.state(), theta, P, R, n_rows, g, Iw, bw, start);
  }
}

template <int N>
void store_state_of(const ff::TrackerStateOf<N>& st, Flat theta, Flat P, Flat R, Flat n_rows, Flat g, Flat Iw, Flat bw,
                    Flat start) {
  check_state_sizes(N, theta, P, R, n_rows, g, Iw, bw, start);
  for (int p = 0; p < N; ++p) {
    theta.data()[p] = st.theta[p];
    for (int q = 0; q < N; ++q) P.data()[N * p + q] = st.P(p, q);
  }
  for (int k = 0; k < ff::kNoiseClasses; ++k) R.data()[k] = st.R[k];
  for (int k = 0; k < ff::kTrackerCounts; ++k) n_rows.data()[k] = st.n_rows[k];
  for (int c = 0; c < 4; ++c) {
    g.data()[c] = st.g[static_cast<std::size_t>(c)];
    start.data()[c] = static_cast<double>(st.start[static_cast<std::size_t>(c)]);
    for (int p = 0; p < N; ++p) {
      bw.data()[N * c + p] = st.bw[static_cast<std::size_t>(c)][p];
      for (int q = 0; q < N; ++q) Iw.data()[N * N * c + N * p + q] = st.Iw[static_cast<std::size_t>(c)](p, q);
    }
  }
}

void store_state(const ff::PayloadTracker& tracker, Flat theta, Flat P, Flat R, Flat n_rows, Flat g, Flat Iw, Flat bw,
                 Flat start) {
  if (tracker.states() == ff::kOffsetStates) {
    store_state_of<ff::kOffsetStates>(tracker.offset_state(), theta, P, R, n_rows, g, Iw, bw, start);
  } else {
    store_state_of<ff::kTrackerStates>(tracker.state(), theta, P, R, n_rows, g, Iw, bw, start);
  }
}

template <int N>
void copy_states(const ff::TrackerStateOf<N>& st, double* th, double* va, std::size_t j) {
  for (int p = 0; p < N; ++p) {
    th[N * j + static_cast<std::size_t>(p)] = st.theta[p];
    va[N * j + static_cast<std::size_t>(p)] = st.P(p, p);
  }
}

// N samples through update(): per sample the ns estimates and variances (as agvdyn.online's
// track_rows), nis, event flags and, with com_offset, (y_c, y_c_std) into `offset` (N, 2); phi (N, 2),
// (N, 3) with com_offset (phi_m, phi_C, phi_y); returns (status, first refused row or -1, events).
std::tuple<int, long, std::vector<Event>> run_tracker(ff::PayloadTracker& tracker, InKind kind, In2 phi, In1 z,
                                                      Out2 theta, Out2 var, Out1 nis, OutKind event,
                                                      std::optional<Out2> offset) {
  const std::size_t n = kind.shape(0);
  const bool com = tracker.states() == ff::kOffsetStates;
  const std::size_t ns = static_cast<std::size_t>(tracker.states()), width = com ? 3 : 2;
  check_shape("phi", phi.shape(0), phi.shape(1), n, width);
  check_shape("z", z.shape(0), 1, n, 1);
  check_shape("theta", theta.shape(0), theta.shape(1), n, ns);
  check_shape("var", var.shape(0), var.shape(1), n, ns);
  check_shape("nis", nis.shape(0), 1, n, 1);
  check_shape("event", event.shape(0), 1, n, 1);
  if (com && !offset) throw std::invalid_argument("offset: expected an (N, 2) array with com_offset");
  if (offset) check_shape("offset", offset->shape(0), offset->shape(1), n, 2);
  double* off = offset ? offset->data() : nullptr;
  std::vector<Event> events;
  int first_status = 0;
  long first_row = -1;
  const std::int64_t* k = kind.data();
  const double* ph = phi.data();
  const double* zz = z.data();
  double* th = theta.data();
  double* va = var.data();
  double* ni = nis.data();
  std::int64_t* ev = event.data();
  {
    nb::gil_scoped_release release;
    ff::TrackerOutput out;
    for (std::size_t j = 0; j < n; ++j) {
      const ff::TrackerRow row{static_cast<ff::RowKind>(k[j]), ph[width * j], ph[width * j + 1], zz[j],
                               com ? ph[width * j + 2] : 0.0};
      const ff::Status status = tracker.update(row, out);
      if (status != ff::Status::ok && first_row < 0) {
        first_status = static_cast<int>(status);
        first_row = static_cast<long>(j);
      }
      if (com) {
        copy_states(tracker.offset_state(), th, va, j);
      } else {
        copy_states(tracker.state(), th, va, j);
      }
      if (off != nullptr) {
        off[2 * j] = out.y_c;
        off[2 * j + 1] = out.y_c_std;
      }
      ni[j] = out.nis;
      ev[j] = out.event;
      for (int e = 0; e < out.n_events; ++e) {
        const ff::TrackerEvent& x = out.events[static_cast<std::size_t>(e)];
        events.emplace_back(x.sample, x.start, x.parameter, x.sign, x.before, x.before_var, x.after, x.after_var);
      }
    }
  }
  return {first_status, first_row, std::move(events)};
}

}  // namespace

NB_MODULE(_core, m) {
  m.doc() = "C++ feed-forward of eq. (21) (library agvdyn_ff, cpp/); use it through agvdyn.ffcpp.";
  nb::class_<ff::Model>(m, "Model")
      .def(
          "__init__",
          [](ff::Model* self, std::tuple<double, double, double, double, double> geometry,
             const std::vector<double>& parameters, double epsilon, double mode_tolerance, double stop_tolerance,
             bool stribeck, Triple d_s, Triple w_s, bool com_offset, double x_c, double y_c, double delay_s) {
            new (self) ff::Model(make_model(geometry, parameters, epsilon, mode_tolerance, stop_tolerance,
                                            make_extension(stribeck, d_s, w_s, com_offset, x_c, y_c, delay_s)));
          },
          nb::arg("geometry"), nb::arg("parameters"), nb::arg("epsilon"),
           nb::arg("mode_tolerance"), nb::arg("stop_tolerance"), nb::kw_only(), nb::arg("stribeck") = false,
           nb::arg("d_s") = Triple{0.0, 0.0, 0.0}, nb::arg("w_s") = Triple{1.0, 1.0, 1.0}, nb::arg("com_offset") = false,
           nb::arg("x_c") = 0.0, nb::arg("y_c") = 0.0, nb::arg("delay_s") = 0.0,
           "Model((l, b, a, r, i_G), parameters[11], epsilon, mode_tolerance, stop_tolerance, *, stribeck, "
           "d_s=(d_sl, d_sr, d_sw), w_s=(w_sl, w_sr, w_sw), com_offset, x_c, y_c, delay_s): ff::Extension")
      .def("feedforward", &feedforward, nb::arg("mode"), nb::arg("alpha"), nb::arg("s_dot"), nb::arg("s_ddot"),
           nb::arg("u"), nb::arg("q_dot"), nb::arg("q_ddot"),
           "Fill u (N, 4) (and q_dot, q_ddot (N, 9) when they have N rows); return (status, first failing row or -1).");
  nb::class_<ff::PayloadTracker>(m, "PayloadTracker")
      .def(
          "__init__",
          [](ff::PayloadTracker* self, std::tuple<double, double> nominal, std::tuple<double, double> nominal_std,
             double dt, const std::map<std::string, double>& settings, double y_c, double y_c_std) {
            new (self) ff::PayloadTracker(make_tracker(nominal, nominal_std, dt, settings, y_c, y_c_std));
          },
          nb::arg("nominal"), nb::arg("nominal_std"), nb::arg("dt"), nb::arg("settings"), nb::kw_only(),
          nb::arg("y_c") = 0.0, nb::arg("y_c_std") = std::numeric_limits<double>::infinity(),
          "PayloadTracker((m_ch, C_ch), (std, std), dt, {setting: value}, *, y_c, y_c_std) "
          "(agvdyn_ff::PayloadTracker::create; com_offset: 1.0 in settings)")
      .def_prop_ro("states", &ff::PayloadTracker::states)
      .def("load_state", &load_state, nb::arg("theta"), nb::arg("P"), nb::arg("R"), nb::arg("n_rows"), nb::arg("g"),
           nb::arg("Iw"), nb::arg("bw"), nb::arg("start"),
           "Set the state from the arrays of agvdyn.online.tracker.TrackerState; the sample count restarts at 0.")
      .def("store_state", &store_state, nb::arg("theta"), nb::arg("P"), nb::arg("R"), nb::arg("n_rows"), nb::arg("g"),
           nb::arg("Iw"), nb::arg("bw"), nb::arg("start"), "Write the state into TrackerState's arrays (in place).")
      .def("begin_log", &ff::PayloadTracker::begin_log, "CUSUMs to zero, samples counted from 0 (a new log).")
      .def("run", &run_tracker, nb::arg("kind"), nb::arg("phi"), nb::arg("z"), nb::arg("theta"), nb::arg("var"),
           nb::arg("nis"), nb::arg("event"), nb::arg("offset").none() = nb::none(),
           "Update with N rows; fill theta, var (N, 8), nis, event (N,); return (status, first refused row or -1, "
           "events [(sample, start, parameter, sign, before, before_var, after, after_var)]). With com_offset: "
           "phi (N, 3) (phi_m, phi_C, phi_y), theta and var (N, 9), offset (N, 2) gets (y_c, y_c_std).")
      .def(
          "update",
          [](ff::PayloadTracker& self, int kind, double phi_m, double phi_C, double z) {
            ff::TrackerOutput out;
            const ff::Status status = self.update(ff::TrackerRow{static_cast<ff::RowKind>(kind), phi_m, phi_C, z}, out);
            return std::make_tuple(static_cast<int>(status), std::make_tuple(out.estimate[0], out.estimate[1]),
                                   std::make_tuple(out.std[0], out.std[1]), out.nis, out.event);
          },
          nb::arg("kind"), nb::arg("phi_m"), nb::arg("phi_C"), nb::arg("z"),
          "One sample: (status, (m_ch, C_ch), (std, std), nis, event flags).")
      .def_prop_ro("event_count", [](const ff::PayloadTracker& self) { return self.event_count(); });
  m.def("status_name", [](int code) { return std::string(ff::to_string(static_cast<ff::Status>(code))); });
  m.def("read_parameter_file", &parameter_file, nb::arg("path"),
        "The C++ reader of parameter files: {'parameters': {name: value}, 'platform': {...} or None, "
        "'model': {friction, delay_s, com_offset} or None, 'extra': {name: value} of the model's extensions}.");
}
