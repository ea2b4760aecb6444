// ff_bench: time of one Model::feedforward call per motion mode, and of one PayloadTracker::update.
//
// For each mode, 1024 random valid setpoints (prototype geometry, Table 2 parameters) are cycled
// through; each of 7 repeats times about 0.1 s of calls; the median repeat is printed as one JSON
// line {"mode": "2", "ns_per_call": ...}. Target: <= 1000 ns per call. Then the same with the model
// beyond the paper (issue 30: Stribeck friction on every joint group and an off-centre centre of mass),
// {"mode": "2", "model": "extended", "ns_per_call": ...}, setpoints at a tenth of the speed (in the
// Stribeck range).
// Mode "track": PayloadTracker::update on 16384 rows of the tracker's model (every kind of row, a
// payload step and a drop, so that CUSUM windows, detections and resets are part of the time), the
// tracker running on through the repeats; {"mode": "track", "ns_per_call": ...}. Target: <= 10 us.
// With the model beyond the paper, the tracker with com_offset (nine states; the x_ch rows carry an
// m_ch y_c column and y_c steps by 4 cm with the payload): {"mode": "track", "model": "com_offset", ...}.
//   ff_bench [--seconds S] [--mode 1|2|3|4|2s|track] [--model paper|extended]
//   (time per repeat, default 0.1; one mode only; one model only)
#include <agvdyn_ff/feedforward.hpp>
#include <agvdyn_ff/tracker.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <vector>

namespace ff = agvdyn::ff;

namespace {

// Median time per call (ns) of run(calls) over 7 repeats of about `seconds` each.
template <typename Run>
double time_per_call(Run&& run, std::size_t first, double seconds) {
  using clock = std::chrono::steady_clock;
  std::size_t calls = first;  // calibrate the number of calls per repeat
  while (true) {
    const auto t0 = clock::now();
    run(calls);
    const double dt = std::chrono::duration<double>(clock::now() - t0).count();
    if (dt > seconds / 4 || calls > (std::size_t{1} << 32)) {
      calls = static_cast<std::size_t>(calls * seconds / std::max(dt, 1e-9)) + 1;
      break;
    }
    calls *= 4;
  }
  std::vector<double> per_call;
  for (int repeat = 0; repeat < 7; ++repeat) {
    const auto t0 = clock::now();
    run(calls);
    const double dt = std::chrono::duration<double>(clock::now() - t0).count();
    per_call.push_back(dt * 1e9 / static_cast<double>(calls));
  }
  std::sort(per_call.begin(), per_call.end());
  return per_call[per_call.size() / 2];
}

int bench_tracker(double seconds, bool com_offset) {
  const ff::Parameters p = ff::Parameters::paper();
  ff::PayloadTracker tracker;
  ff::TrackerSettings settings;
  settings.com_offset = com_offset;
  if (ff::PayloadTracker::create(ff::Vector2(p.m_ch, p.C_ch), ff::Vector2(1.0, 1.2), 0.002, settings, &tracker) !=
      ff::Status::ok) {
    return 2;
  }
  // rows of z = phi_m m + phi_C C + bias + noise in runs of 512 rows per kind (one in 16 without a row)
  constexpr std::size_t n = 16384;
  std::vector<ff::TrackerRow> rows(n);
  std::mt19937_64 rng(2);
  std::normal_distribution<double> noise(0.0, 1.0);
  const double pi = 3.14159265358979323846;
  for (std::size_t k = 0; k < n; ++k) {
    const int kind = 1 + static_cast<int>((k / 512) % ff::kRowKinds);  // every kind: 7, 8 car-like x_ch rows
    const double wave = std::sin(2 * pi * static_cast<double>(k) / 400.0);
    const double m = p.m_ch + (k >= n / 2 ? 300.0 : 0.0), C = p.C_ch + (k >= n / 2 ? 60.0 : 0.0);
    ff::TrackerRow& r = rows[k];
    r.kind = k % 16 == 15 ? ff::RowKind::none : static_cast<ff::RowKind>(kind);
    r.phi_m = (kind <= 4 || kind >= 7) ? 0.4 * wave : 0.0;
    r.phi_C = (kind == 5 || kind == 6) ? 1.0 * wave : 0.05 * wave;
    r.phi_y = com_offset && (kind <= 2 || kind >= 7) ? 0.3 * std::cos(2 * pi * static_cast<double>(k) / 400.0) : 0.0;
    r.z = r.phi_m * m + r.phi_C * C + r.phi_y * (k >= n / 2 ? 12.0 : 0.0) + 0.5 * kind + noise(rng);
  }
  ff::TrackerOutput out;
  double sink = 0;
  long bad = 0;
  auto run = [&](std::size_t calls) {
    for (std::size_t c = 0; c < calls; ++c) {
      bad += tracker.update(rows[c % n], out) != ff::Status::ok;
      sink += out.estimate[0];
    }
  };
  const double ns = time_per_call(run, n, seconds);
  if (bad) return 3;
  if (com_offset) {
    std::printf("{\"mode\": \"track\", \"model\": \"com_offset\", \"ns_per_call\": %.1f, \"events\": %lld}\n", ns,
                static_cast<long long>(tracker.event_count()));
  } else {
    std::printf("{\"mode\": \"track\", \"ns_per_call\": %.1f, \"events\": %lld}\n", ns,
                static_cast<long long>(tracker.event_count()));
  }
  if (sink == 12345.678) std::printf("\n");  // keep the results alive
  return 0;
}

// Breakaway 1.3 d_c on every joint group (w_s 0.05, 0.05, 0.02 rad/s), centre of mass at (0.15, -0.1) m.
ff::Extension bench_extension(const ff::Parameters& p) {
  ff::Extension e;
  e.stribeck = true;
  e.d_s = {1.3 * p.d_cl, 1.3 * p.d_cr, 1.3 * p.d_cw};
  e.w_s = {0.05, 0.05, 0.02};
  e.com_offset = true;
  e.x_c = 0.15;
  e.y_c = -0.1;
  return e;
}

int bench_modes(const ff::Model& model, const char* only, const char* name, double speed, double seconds);

}  // namespace

int main(int argc, char** argv) {
  double seconds = 0.1;
  const char* only = nullptr;
  const char* model_only = nullptr;
  for (int k = 1; k < argc; ++k) {
    if (std::strcmp(argv[k], "--seconds") == 0 && k + 1 < argc) seconds = std::atof(argv[++k]);
    else if (std::strcmp(argv[k], "--mode") == 0 && k + 1 < argc) only = argv[++k];
    else if (std::strcmp(argv[k], "--model") == 0 && k + 1 < argc) model_only = argv[++k];
  }
  ff::Model model, extended;
  const ff::Parameters p = ff::Parameters::paper();
  if (ff::Model::create(ff::Geometry{}, p, ff::Settings{}, &model) != ff::Status::ok) return 2;
  if (model.with_extension(bench_extension(p), &extended) != ff::Status::ok) return 2;
  if (model_only == nullptr || std::strcmp(model_only, "paper") == 0) {
    if (const int rc = bench_modes(model, only, nullptr, 1.0, seconds); rc != 0) return rc;
  }
  if (model_only == nullptr || std::strcmp(model_only, "extended") == 0) {
    if (const int rc = bench_modes(extended, only, "extended", 0.1, seconds); rc != 0) return rc;
  }
  const bool track = only == nullptr ? model_only == nullptr : std::strcmp(only, "track") == 0;
  if (track && (model_only == nullptr || std::strcmp(model_only, "paper") == 0)) {
    if (const int rc = bench_tracker(seconds, false); rc != 0) return rc;
  }
  if (track && (model_only == nullptr || std::strcmp(model_only, "extended") == 0)) return bench_tracker(seconds, true);
  return 0;
}

namespace {

// One JSON line per mode (all, or `only`): the median ns per Model::feedforward call on 1024 random
// setpoints with |s_dot| <= speed; `name` the model's label in the line (nullptr: none, the paper's).
int bench_modes(const ff::Model& model, const char* only, const char* name, double speed, double seconds) {
  const ff::Geometry g = model.geometry();
  const double pi = 3.14159265358979323846;
  const double k = g.b / g.l, limit = std::atan2(g.l, g.b), rot = std::atan2(g.l, g.b);
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const ff::Mode modes[] = {ff::Mode::parking, ff::Mode::car_like, ff::Mode::lateral, ff::Mode::rotation,
                            ff::Mode::straight};
  constexpr std::size_t n = 1024;
  for (ff::Mode mode : modes) {
    if (only != nullptr && std::strcmp(only, ff::label(mode)) != 0) continue;
    std::vector<ff::Setpoint> inputs(n);
    for (auto& sp : inputs) {
      sp.mode = mode;
      switch (mode) {
        case ff::Mode::parking: sp.alpha = ff::Vector2(unit(rng), unit(rng)) * (pi / 2); break;
        case ff::Mode::car_like: {
          const double av = 0.97 * limit * unit(rng), s = std::sin(av), c = std::cos(av);
          sp.alpha = ff::Vector2(std::atan2(s, c - k * s), std::atan2(s, c + k * s));
          break;
        }
        case ff::Mode::lateral: sp.alpha = ff::Vector2(-pi / 2, pi / 2); break;
        case ff::Mode::rotation: sp.alpha = ff::Vector2(-rot, rot); break;
        case ff::Mode::straight: sp.alpha = ff::Vector2::Zero(); break;
      }
      sp.s_dot = ff::Vector2(unit(rng), unit(rng)) * speed;
      sp.s_ddot = ff::Vector2(unit(rng), unit(rng));
    }
    ff::Vector4 u;
    double sink = 0;
    auto run = [&](std::size_t calls) {
      for (std::size_t c = 0; c < calls; ++c) {
        if (model.feedforward(inputs[c % n], u) != ff::Status::ok) std::abort();
        sink += u[c & 3];
      }
    };
    const double ns = time_per_call(run, n, seconds);
    if (name == nullptr) {
      std::printf("{\"mode\": \"%s\", \"ns_per_call\": %.1f}\n", ff::label(mode), ns);
    } else {
      std::printf("{\"mode\": \"%s\", \"model\": \"%s\", \"ns_per_call\": %.1f}\n", ff::label(mode), name, ns);
    }
    if (sink == 12345.678) std::printf("\n");  // keep the results alive
  }
  return 0;
}

}  // namespace
