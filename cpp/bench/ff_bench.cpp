// ff_bench: time of one Model::feedforward call per motion mode.
//
// For each mode, 1024 random valid setpoints (prototype geometry, Table 2 parameters) are cycled
// through; each of 7 repeats times about 0.1 s of calls; the median repeat is printed as one JSON
// line {"mode": "2", "ns_per_call": ...}. Target: <= 1000 ns per call.
//   ff_bench [--seconds S]   (time per repeat, default 0.1)
#include <agvdyn_ff/feedforward.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <vector>

namespace ff = agvdyn::ff;

int main(int argc, char** argv) {
  double seconds = 0.1;
  for (int k = 1; k < argc; ++k) {
    if (std::strcmp(argv[k], "--seconds") == 0 && k + 1 < argc) seconds = std::atof(argv[++k]);
  }
  ff::Model model;
  const ff::Geometry g{};
  if (ff::Model::create(g, ff::Parameters::paper(), ff::Settings{}, &model) != ff::Status::ok) return 2;
  const double pi = 3.14159265358979323846;
  const double k = g.b / g.l, limit = std::atan2(g.l, g.b), rot = std::atan2(g.l, g.b);
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const ff::Mode modes[] = {ff::Mode::parking, ff::Mode::car_like, ff::Mode::lateral, ff::Mode::rotation,
                            ff::Mode::straight};
  constexpr std::size_t n = 1024;
  for (ff::Mode mode : modes) {
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
      sp.s_dot = ff::Vector2(unit(rng), unit(rng));
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
    using clock = std::chrono::steady_clock;
    // calibrate the number of calls per repeat
    std::size_t calls = n;
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
    std::printf("{\"mode\": \"%s\", \"ns_per_call\": %.1f}\n", ff::label(mode), per_call[per_call.size() / 2]);
    if (sink == 12345.678) std::printf("\n");  // keep the results alive
  }
  return 0;
}
