// PayloadTracker against the Python reference (agvdyn.online.tracker) on the shared vectors
// (tracker_vectors.json + data/tracker_sequence.csv, written by make_vectors.py; with com_offset
// tracker_offset_vectors.json + data/tracker_offset_sequence.csv): every output of every sample to
// 1e-9 relative, the events, the final state; plus its own properties: no heap allocation per
// update, status codes, begin_log, set_state, the offset's start and reports.
#include <agvdyn_ff/tracker.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "document.hpp"

namespace ff = agvdyn::ff;
using agvdyn::ff::detail::Node;

long agvdyn_ff_test_allocations();  // test_feedforward.cpp: operator new calls so far

namespace {

struct Sample {
  int log = 0;
  ff::TrackerRow row;
  double m_ch = 0, C_ch = 0, m_std = 0, C_std = 0, nis = 0;
  double y_c = 0, y_std = 0;  // with com_offset
  int event = 0;
};

struct TrackerVectors {
  Node root;
  std::vector<Sample> samples;
  double relative = 0;
  ff::TrackerSettings settings;
  ff::Vector2 nominal = ff::Vector2::Zero(), nominal_std = ff::Vector2::Zero();
  double dt = 0;
};

double number(const Node* node) {
  double v = 0;
  EXPECT_TRUE(node != nullptr && node->number(&v)) << (node ? node->text : std::string("missing key"));
  return v;
}

std::vector<double> numbers(const Node* node) {
  std::vector<double> out;
  if (node == nullptr || !node->is_sequence()) {
    ADD_FAILURE() << "expected a list";
    return out;
  }
  for (const Node& v : node->values) out.push_back(number(&v));
  return out;
}

// The vectors of the tracker without (tracker_vectors.json) or with the centre-of-mass offset
// (tracker_offset_vectors.json: phi_y in the rows, y_c and its std in the outputs).
TrackerVectors read_vectors(bool offset) {
    TrackerVectors out;
    std::string error;
    const std::string dir = AGVDYN_FF_TEST_DATA;
    if (!agvdyn::ff::detail::read_document(dir + (offset ? "/tracker_offset_vectors.json" : "/tracker_vectors.json"),
                                           &out.root, &error)) {
      ADD_FAILURE() << error;
      return out;
    }
    out.relative = number(out.root.find("tolerance")->find("relative"));
    const Node& s = *out.root.find("settings");
    ff::TrackerSettings& t = out.settings;
    t.change_size = number(s.find("change_size"));
    t.gate = number(s.find("gate"));
    t.correlation = number(s.find("correlation"));
    t.rotation_correlation = number(s.find("rotation_correlation"));
    t.threshold = number(s.find("threshold"));
    t.random_walk = number(s.find("random_walk"));
    t.bias_walk = number(s.find("bias_walk"));
    t.reset_std = number(s.find("reset_std"));
    t.noise_time = number(s.find("noise_time"));
    t.warm_rows = static_cast<int>(number(s.find("warm_rows")));
    t.initial_std = number(s.find("initial_std"));
    t.bias_std = number(s.find("bias_std"));
    t.twin_bias_std = number(s.find("twin_bias_std"));
    t.noise = number(s.find("noise"));
    if (offset) {
      t.com_offset = true;
      t.offset_change = number(s.find("offset_change"));
      t.offset_std = number(s.find("offset_std"));
      t.offset_walk = number(s.find("offset_walk"));
    }
    const auto nominal = numbers(out.root.find("nominal")), nominal_std = numbers(out.root.find("nominal_std"));
    out.nominal = ff::Vector2(nominal.at(0), nominal.at(1));
    out.nominal_std = ff::Vector2(nominal_std.at(0), nominal_std.at(1));
    out.dt = number(out.root.find("dt"));
    std::ifstream in(dir + "/" + out.root.find("sequence")->text);
    std::string line;
    const char* header = offset ? "log,kind,phi_m,phi_C,phi_y,z,m_ch,C_ch,m_ch_std,C_ch_std,y_c,y_c_std,nis,event"
                                : "log,kind,phi_m,phi_C,z,m_ch,C_ch,m_ch_std,C_ch_std,nis,event";
    if (!std::getline(in, line) || line != header) {
      ADD_FAILURE() << "tracker sequence: unexpected header " << line;
      return out;
    }
    const int columns = offset ? 14 : 11;
    while (std::getline(in, line)) {
      if (line.empty()) continue;
      double c[14];
      const char* p = line.c_str();
      for (int k = 0; k < columns; ++k) {
        char* end = nullptr;
        c[k] = std::strtod(p, &end);
        if (end == p) {
          ADD_FAILURE() << "tracker sequence: bad number in " << line;
          return out;
        }
        p = *end == ',' ? end + 1 : end;
      }
      Sample smp;
      smp.log = static_cast<int>(c[0]);
      const int y = offset ? 1 : 0;  // the columns after phi_C move by one with phi_y
      smp.row = ff::TrackerRow{static_cast<ff::RowKind>(static_cast<int>(c[1])), c[2], c[3], c[4 + y],
                               offset ? c[4] : 0.0};
      smp.m_ch = c[5 + y];
      smp.C_ch = c[6 + y];
      smp.m_std = c[7 + y];
      smp.C_std = c[8 + y];
      if (offset) {
        smp.y_c = c[10];
        smp.y_std = c[11];
      }
      smp.nis = c[9 + 3 * y];
      smp.event = static_cast<int>(c[10 + 3 * y]);
      out.samples.push_back(smp);
    }
    return out;
}

const TrackerVectors& vectors() {
  static const TrackerVectors v = read_vectors(false);
  return v;
}

const TrackerVectors& offset_vectors() {
  static const TrackerVectors v = read_vectors(true);
  return v;
}

// |x - ref| / max(|ref|, 1), asserting the vectors' rule
double deviation(double x, double ref, double relative, const char* what, std::size_t k) {
  if (std::isnan(ref)) {
    EXPECT_TRUE(std::isnan(x)) << what << " at sample " << k << ": " << x << ", expected NaN";
    return 0;
  }
  const double d = std::abs(x - ref) / std::max(std::abs(ref), 1.0);
  EXPECT_LE(d, relative) << what << " at sample " << k << ": " << x << " vs " << ref;
  return d;
}

ff::PayloadTracker make(const TrackerVectors& v) {
  ff::PayloadTracker tracker;
  EXPECT_EQ(ff::PayloadTracker::create(v.nominal, v.nominal_std, v.dt, v.settings, &tracker), ff::Status::ok);
  return tracker;
}

}  // namespace

TEST(TrackerVectors, SequenceHasBothLogsStepsAndEveryKind) {
  const TrackerVectors& v = vectors();
  ASSERT_GE(v.samples.size(), 5000u);
  int kinds[ff::kRowKinds + 1] = {};
  for (const Sample& s : v.samples) ++kinds[static_cast<int>(s.row.kind)];
  for (int k = 0; k <= ff::kRowKinds; ++k) EXPECT_GT(kinds[k], 100) << ff::label(static_cast<ff::RowKind>(k));
  EXPECT_GE(v.root.find("events")->values.size(), 3u);
}

namespace {

// The final state against the reference's (theta, P, R, n_rows, g, start), N states; the largest deviation.
template <int N>
double check_final(const ff::TrackerStateOf<N>& st, const Node& f, double relative) {
  double worst = 0;
  const auto theta = numbers(f.find("theta")), P = numbers(f.find("P")), R = numbers(f.find("R")),
             n_rows = numbers(f.find("n_rows")), g = numbers(f.find("g")), start = numbers(f.find("start"));
  EXPECT_EQ(theta.size(), static_cast<std::size_t>(N));
  EXPECT_EQ(P.size(), static_cast<std::size_t>(N * N));
  if (theta.size() != static_cast<std::size_t>(N) || P.size() != static_cast<std::size_t>(N * N)) return 1.0;
  for (std::size_t k = 0; k < N; ++k) worst = std::max(worst, deviation(st.theta[k], theta[k], relative, "final theta", k));
  for (std::size_t k = 0; k < N * N; ++k) {
    worst = std::max(worst, deviation(st.P(k / N, k % N), P[k], relative, "final P", k));
  }
  EXPECT_EQ(R.size(), static_cast<std::size_t>(ff::kNoiseClasses));
  EXPECT_EQ(n_rows.size(), static_cast<std::size_t>(ff::kTrackerCounts));
  for (std::size_t k = 0; k < ff::kNoiseClasses; ++k) {
    worst = std::max(worst, deviation(st.R[k], R.at(k), relative, "final R", k));
  }
  for (std::size_t k = 0; k < ff::kTrackerCounts; ++k) EXPECT_EQ(st.n_rows[k], n_rows.at(k));
  for (std::size_t k = 0; k < 4; ++k) {
    worst = std::max(worst, deviation(st.g[k], g.at(k), relative, "final g", k));
    EXPECT_EQ(st.start[k], static_cast<std::int64_t>(start.at(k)));
  }
  return worst;
}

// Every output of every sample, the events and the final state of a tracker run through the vectors.
void check_vectors(const TrackerVectors& v, bool offset) {
  ASSERT_FALSE(v.samples.empty());
  ff::PayloadTracker tracker = make(v);
  ASSERT_EQ(tracker.states(), offset ? ff::kOffsetStates : ff::kTrackerStates);
  std::vector<std::pair<int, ff::TrackerEvent>> events;
  double worst = 0;
  int log = 0;
  ff::TrackerOutput out;
  for (std::size_t k = 0; k < v.samples.size(); ++k) {
    const Sample& s = v.samples[k];
    if (s.log != log) {
      tracker.begin_log();
      log = s.log;
    }
    ASSERT_EQ(tracker.update(s.row, out), ff::Status::ok) << "sample " << k;
    worst = std::max(worst, deviation(out.estimate[0], s.m_ch, v.relative, "m_ch", k));
    worst = std::max(worst, deviation(out.estimate[1], s.C_ch, v.relative, "C_ch", k));
    worst = std::max(worst, deviation(out.std[0], s.m_std, v.relative, "m_ch_std", k));
    worst = std::max(worst, deviation(out.std[1], s.C_std, v.relative, "C_ch_std", k));
    worst = std::max(worst, deviation(out.nis, s.nis, v.relative, "nis", k));
    if (offset) {
      worst = std::max(worst, deviation(out.y_c, s.y_c, v.relative, "y_c", k));
      if (std::isinf(s.y_std)) {
        EXPECT_TRUE(std::isinf(out.y_c_std)) << "y_c_std at sample " << k << ": " << out.y_c_std << ", expected inf";
      } else {
        worst = std::max(worst, deviation(out.y_c_std, s.y_std, v.relative, "y_c_std", k));
      }
    } else {
      EXPECT_TRUE(std::isnan(out.y_c) && std::isinf(out.y_c_std));  // not tracked
    }
    ASSERT_EQ(out.event, s.event) << "sample " << k;
    for (int e = 0; e < out.n_events; ++e) events.emplace_back(log, out.events[static_cast<std::size_t>(e)]);
  }
  // events
  const Node& ref_events = *v.root.find("events");
  ASSERT_EQ(events.size(), ref_events.values.size());
  for (std::size_t k = 0; k < events.size(); ++k) {
    const Node& r = ref_events.values[k];
    const ff::TrackerEvent& e = events[k].second;
    EXPECT_EQ(events[k].first, static_cast<int>(number(r.find("log"))));
    EXPECT_EQ(e.parameter, static_cast<int>(number(r.find("parameter"))));
    EXPECT_EQ(e.sign, static_cast<int>(number(r.find("sign"))));
    EXPECT_EQ(e.sample, static_cast<std::int64_t>(number(r.find("sample"))));
    EXPECT_EQ(e.start, static_cast<std::int64_t>(number(r.find("start"))));
    worst = std::max(worst, deviation(e.before, number(r.find("before")), v.relative, "event before", k));
    worst = std::max(worst, deviation(e.before_var, number(r.find("before_var")), v.relative, "event before_var", k));
    worst = std::max(worst, deviation(e.after, number(r.find("after")), v.relative, "event after", k));
    worst = std::max(worst, deviation(e.after_var, number(r.find("after_var")), v.relative, "event after_var", k));
  }
  EXPECT_EQ(tracker.event_count(), static_cast<std::int64_t>(events.size()));
  const Node& f = *v.root.find("final");
  worst = std::max(worst, offset ? check_final(tracker.offset_state(), f, v.relative)
                                 : check_final(tracker.state(), f, v.relative));
  ::testing::Test::RecordProperty("max_relative_deviation", std::to_string(worst));
  std::printf("[ tracker  ] %s%zu samples, %zu events, largest relative deviation %.3g\n", offset ? "com_offset: " : "",
              v.samples.size(), events.size(), worst);
}

}  // namespace

TEST(TrackerVectors, EveryOutputEqualsThePythonReference) { check_vectors(vectors(), false); }

// With com_offset: nine states, phi_y in the car-like x_ch rows, y_c and its std (inf until informed).
TEST(TrackerVectors, WithTheOffsetEveryOutputEqualsThePythonReference) {
  const TrackerVectors& v = offset_vectors();
  int informed = 0, uninformed = 0, turning = 0;
  for (const Sample& s : v.samples) {
    (std::isfinite(s.y_std) ? informed : uninformed) += 1;
    turning += s.row.phi_y != 0.0;
  }
  EXPECT_GT(informed, 1000);  // the vectors reach both branches of y_c's std
  EXPECT_GT(uninformed, 1000);
  EXPECT_GT(turning, 1000);
  EXPECT_GE(v.root.find("events")->values.size(), 3u);
  check_vectors(v, true);
}

TEST(Tracker, UpdateDoesNotAllocate) {
  for (const TrackerVectors* v : {&vectors(), &offset_vectors()}) {
    ff::PayloadTracker tracker = make(*v);
    ff::TrackerOutput out;
    const long before = agvdyn_ff_test_allocations();
    for (const Sample& s : v->samples) tracker.update(s.row, out);
    tracker.begin_log();
    EXPECT_EQ(agvdyn_ff_test_allocations() - before, 0) << (v->settings.com_offset ? "com_offset" : "paper");
  }
}

// With com_offset: m_ch y_c starts at m_ch y_c0 with the variance (m_ch sd)^2 + y_c0^2 var(m_ch), sd the given
// std (at least offset_change) or the prior offset_std; y_c's std is inf while it is at the prior; a
// NaN phi_y is refused only when the offset is tracked; a state of the other size is refused.
TEST(Tracker, OffsetStartAndRefusals) {
  const TrackerVectors& v = offset_vectors();
  const double m = v.nominal[0], var_m = std::pow(std::max(v.nominal_std[0], v.settings.initial_std * m), 2);
  ff::PayloadTracker prior, given;
  ASSERT_EQ(ff::PayloadTracker::create(v.nominal, v.nominal_std, v.dt, v.settings, &prior), ff::Status::ok);
  ASSERT_EQ(ff::PayloadTracker::create(v.nominal, v.nominal_std, 0.05, 0.001, v.dt, v.settings, &given), ff::Status::ok);
  EXPECT_EQ(prior.states(), ff::kOffsetStates);
  EXPECT_EQ(prior.offset_state().theta[ff::kOffsetState], 0.0);
  EXPECT_DOUBLE_EQ(prior.offset_state().P(ff::kOffsetState, ff::kOffsetState), std::pow(m * v.settings.offset_std, 2));
  const auto& g = given.offset_state();
  EXPECT_DOUBLE_EQ(g.theta[ff::kOffsetState], m * 0.05);
  EXPECT_DOUBLE_EQ(g.P(ff::kOffsetState, ff::kOffsetState), std::pow(m * v.settings.offset_change, 2) + 0.0025 * var_m);
  EXPECT_DOUBLE_EQ(g.P(0, ff::kOffsetState), 0.05 * var_m);
  EXPECT_EQ(g.P(1, ff::kOffsetState), 0.0);
  ff::TrackerOutput out;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(prior.update(ff::TrackerRow{ff::RowKind::x_plus, 0.3, 0.0, 250.0, nan}, out), ff::Status::non_finite_input);
  EXPECT_EQ(out.y_c, 0.0);
  EXPECT_TRUE(std::isinf(out.y_c_std));  // at its prior: not informed
  EXPECT_EQ(given.update(ff::TrackerRow{ff::RowKind::none, 0, 0, 0, 0}, out), ff::Status::ok);
  EXPECT_DOUBLE_EQ(out.y_c, 0.05);
  EXPECT_NEAR(out.y_c_std, v.settings.offset_change, 1e-12);  // the delta method gives back y_c's own std
  ff::PayloadTracker paper = make(vectors());
  EXPECT_EQ(paper.update(ff::TrackerRow{ff::RowKind::x_plus, 0.3, 0.0, 250.0, nan}, out), ff::Status::ok);  // phi_y unused
  EXPECT_EQ(paper.set_state(prior.offset_state()), ff::Status::invalid_model);
  EXPECT_EQ(prior.set_state(paper.state()), ff::Status::invalid_model);
  EXPECT_EQ(ff::PayloadTracker::create(v.nominal, v.nominal_std, nan, 0.01, v.dt, v.settings, &given),
            ff::Status::invalid_model);
  // a tracker given another's state continues identically
  ff::PayloadTracker a = make(v), b = make(v);
  ff::TrackerOutput out_a, out_b;
  for (std::size_t k = 0; k < 4500; ++k) a.update(v.samples[k].row, out_a);
  ASSERT_EQ(b.set_state(a.offset_state()), ff::Status::ok);
  for (std::size_t k = 4500; k < 6000; ++k) {
    a.update(v.samples[k].row, out_a);
    b.update(v.samples[k].row, out_b);
  }
  EXPECT_EQ(out_a.y_c, out_b.y_c);
  EXPECT_EQ(a.offset_state().P, b.offset_state().P);
}

TEST(Tracker, RefusesBadRowsAndSettings) {
  const TrackerVectors& v = vectors();
  ff::PayloadTracker tracker = make(v);
  ff::TrackerOutput out;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(tracker.update(ff::TrackerRow{static_cast<ff::RowKind>(9), 0.1, 0.0, 1.0}, out), ff::Status::unknown_row_kind);
  EXPECT_EQ(tracker.update(ff::TrackerRow{static_cast<ff::RowKind>(-1), 0.1, 0.0, 1.0}, out), ff::Status::unknown_row_kind);
  EXPECT_STREQ(ff::to_string(ff::Status::unknown_row_kind), "unknown_row_kind");
  EXPECT_EQ(tracker.update(ff::TrackerRow{ff::RowKind::x_plus, nan, 0.0, 1.0}, out), ff::Status::non_finite_input);
  EXPECT_EQ(tracker.update(ff::TrackerRow{ff::RowKind::gamma_minus, 0.0, 0.2, INFINITY}, out), ff::Status::non_finite_input);
  EXPECT_TRUE(std::isnan(out.nis));
  EXPECT_EQ(out.estimate, v.nominal);  // refused rows leave the state
  EXPECT_EQ(tracker.state().n_rows.sum(), 0.0);
  EXPECT_EQ(tracker.state().sample, 4);  // but count as samples
  EXPECT_EQ(tracker.update(ff::TrackerRow{ff::RowKind::none, nan, nan, nan}, out), ff::Status::ok);
  ff::PayloadTracker bad;
  ff::TrackerSettings s = v.settings;
  s.threshold = 0;
  EXPECT_EQ(ff::PayloadTracker::create(v.nominal, v.nominal_std, v.dt, s, &bad), ff::Status::invalid_model);
  EXPECT_EQ(ff::PayloadTracker::create(ff::Vector2(-1, 2), v.nominal_std, v.dt, v.settings, &bad), ff::Status::invalid_model);
  EXPECT_EQ(ff::PayloadTracker::create(v.nominal, ff::Vector2(nan, 0), v.dt, v.settings, &bad), ff::Status::invalid_model);
  EXPECT_EQ(ff::PayloadTracker::create(v.nominal, v.nominal_std, 0.0, v.settings, &bad), ff::Status::invalid_model);
  EXPECT_EQ(ff::PayloadTracker::create(v.nominal, v.nominal_std, v.dt, v.settings, nullptr), ff::Status::invalid_model);
  ff::PayloadTracker::State st = tracker.state();
  st.P(3, 3) = nan;
  EXPECT_EQ(tracker.set_state(st), ff::Status::non_finite_input);
}

TEST(Tracker, InitialStateAndStateRoundTrip) {
  const TrackerVectors& v = vectors();
  ff::PayloadTracker a = make(v);
  const auto& st = a.state();
  EXPECT_EQ(st.theta.head<2>(), v.nominal);
  EXPECT_DOUBLE_EQ(a.std()[0], std::max(v.nominal_std[0], v.settings.initial_std * v.nominal[0]));
  EXPECT_DOUBLE_EQ(std::sqrt(st.P(5, 5)), v.settings.bias_std);
  EXPECT_EQ(st.R, Eigen::Vector4d::Constant(v.settings.noise));
  // a tracker given another's state continues identically
  ff::TrackerOutput out_a, out_b;
  const std::size_t half = 1500;
  for (std::size_t k = 0; k < half; ++k) a.update(v.samples[k].row, out_a);
  ff::PayloadTracker b = make(v);
  ASSERT_EQ(b.set_state(a.state()), ff::Status::ok);
  for (std::size_t k = half; k < 3000; ++k) {
    a.update(v.samples[k].row, out_a);
    b.update(v.samples[k].row, out_b);
  }
  EXPECT_EQ(out_a.estimate, out_b.estimate);
  EXPECT_EQ(a.state().P, b.state().P);
  EXPECT_STREQ(ff::label(ff::RowKind::gamma_minus), "gamma_ch-");
  EXPECT_STREQ(ff::label(ff::RowKind::x_car_minus), "x_ch- car-like");
  EXPECT_STREQ(ff::label(static_cast<ff::RowKind>(9)), "?");
}

// A pick-up changes m_ch and C_ch together: an m_ch alarm from straight rows (no C_ch information in
// its window) keeps C_ch's value with the reset variance (reset_std C_ch)^2; the noise estimate learns
// nothing while the kind warms up. White rows: threshold 12 (Page's CUSUM alarms every ~e^h white rows).
TEST(Tracker, AChangeResetsBothPayloadParameters) {
  ff::TrackerSettings s;
  s.correlation = 1.0;
  s.rotation_correlation = 1.0;
  s.threshold = 12.0;
  const ff::Vector2 nominal(842.0, 286.0);
  ff::PayloadTracker tracker;
  ASSERT_EQ(ff::PayloadTracker::create(nominal, ff::Vector2::Zero(), 0.002, s, &tracker), ff::Status::ok);
  ff::TrackerOutput out;
  for (int k = 0; k < s.warm_rows; ++k) {  // warm-up: the noise keeps its prior
    const double phi = 0.4 * std::sin(0.0157 * k);
    tracker.update(ff::TrackerRow{ff::RowKind::x_plus, phi, 0.0, phi * 842.0 + 7.0 + 1.5 * std::sin(2.1 * k)}, out);
  }
  EXPECT_EQ(tracker.state().R[0], s.noise);
  int fired = -1;
  for (int k = s.warm_rows; k < 20000 && fired < 0; ++k) {
    const double phi = 0.4 * std::sin(0.0157 * k);
    const double m = k < 6000 ? 842.0 : 1094.6;  // +30 % at row 6000
    const double C_before = tracker.estimate()[1];
    tracker.update(ff::TrackerRow{ff::RowKind::x_plus, phi, 0.0, phi * m + 7.0 + 1.5 * std::sin(2.1 * k)}, out);
    if (out.event != 0) {
      fired = k;
      EXPECT_EQ(out.n_events, 1);
      EXPECT_EQ(out.events[0].parameter, 0);
      EXPECT_EQ(out.events[0].sign, 1);
      EXPECT_GE(out.events[0].start, 6000 - 500);
      EXPECT_NEAR(out.estimate[0] / 1094.6, 1.0, 0.05);
      EXPECT_NEAR(out.estimate[1], C_before, 1e-9 * C_before);
      EXPECT_NEAR(out.std[1], s.reset_std * nominal[1], 1e-9 * nominal[1]);
    }
  }
  ASSERT_GT(fired, 6000);
  EXPECT_LT(fired, 6500);
}
