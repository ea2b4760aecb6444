// Example: a 500 Hz feed-forward loop with agvdyn_ff.
//
//   control_loop PARAMS.yaml FEEDFORWARD.csv [--platform PLATFORM.yaml] [--rate HZ] [--free-run]
//                [--quiet] [--check TOL] [--track ROWS.csv]
//
// PARAMS: a parameter file of `agvdyn identify` (YAML or JSON; its `platform` is the vehicle; a
// `model:` block, the model beyond the paper: Stribeck friction and an off-centre chassis enter the
// torques, a torque delay does not: see ff::Extension).
// FEEDFORWARD.csv: a table of `agvdyn feedforward` (one row per 2 ms: t, segment, mode, alpha_l,
// alpha_r, the planned q_dot, ...). Everything that may allocate happens before the loop: reading
// the files, building the Model, turning each row into a Setpoint (s_dot = H_k^+ q_dot, s_ddot by
// central differences of s_dot within a segment, as a planner streaming velocities would). The
// loop itself waits for its tick, calls Model::feedforward (no allocation, no exceptions) and
// stores the torques; they are printed afterwards as CSV `t,mode,m_fl,m_rl,m_fr,m_rr`.
//
// stderr gets a summary: compute time per call, late ticks, error codes, and (when the table has
// m_fl..m_rr) the largest deviation from the table's torques relative to its largest torque;
// --check TOL fails (exit 1) above TOL. --free-run runs without waiting for the ticks.
//
// --track ROWS.csv: the payload tracker in the loop. ROWS.csv holds one causal row per tick (columns
// kind, phi_m, phi_C, z of agvdyn.online.rows; optional `log`: a new log restarts the CUSUMs; optional
// m_ch, C_ch: reference estimates, e.g. Python's). Each tick first runs PayloadTracker::update on
// its row, then the feed-forward with the tracked m_ch, C_ch (Model::with_parameters); the loop
// runs one tick per row, the table's setpoints repeating. The CSV gains the columns m_ch, C_ch,
// event; stderr the tracker's time per tick, events and final estimates; with reference columns
// the largest relative deviation from them, which --check then applies to (the table's torques
// were computed with the file's parameters and are only compared for information).
#include <agvdyn_ff/feedforward.hpp>
#include <agvdyn_ff/parameter_file.hpp>
#include <agvdyn_ff/tracker.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace ff = agvdyn::ff;

namespace {

struct Table {
  std::vector<std::string> columns;
  std::vector<std::vector<std::string>> rows;
  int index(const std::string& name) const {
    for (std::size_t k = 0; k < columns.size(); ++k) {
      if (columns[k] == name) return static_cast<int>(k);
    }
    return -1;
  }
};

std::vector<std::string> split_csv(const std::string& line) {
  std::vector<std::string> out;
  std::string cell;
  bool quoted = false;
  for (char c : line) {
    if (c == '"') {
      quoted = !quoted;
    } else if (c == ',' && !quoted) {
      out.push_back(cell);
      cell.clear();
    } else if (c != '\r') {
      cell += c;
    }
  }
  out.push_back(cell);
  return out;
}

bool read_csv(const std::string& path, Table* table, std::string* error) {
  std::ifstream in(path);
  if (!in) {
    *error = path + ": cannot be read";
    return false;
  }
  std::string line;
  if (!std::getline(in, line)) {
    *error = path + ": empty file";
    return false;
  }
  table->columns = split_csv(line);
  int number = 1;
  while (std::getline(in, line)) {
    ++number;
    if (line.empty() || line == "\r") continue;
    auto cells = split_csv(line);
    if (cells.size() != table->columns.size()) {
      *error = path + ": row " + std::to_string(number) + " has " + std::to_string(cells.size()) + " cells, expected " +
               std::to_string(table->columns.size());
      return false;
    }
    table->rows.push_back(std::move(cells));
  }
  return true;
}

bool to_number(const std::string& text, double* out) {
  char* end = nullptr;
  *out = std::strtod(text.c_str(), &end);
  return end != text.c_str() && *end == '\0';
}

void usage() {
  std::fprintf(stderr,
               "usage: control_loop PARAMS.yaml FEEDFORWARD.csv [--platform PLATFORM.yaml] [--rate HZ] "
               "[--free-run] [--quiet] [--check TOL] [--track ROWS.csv]\n");
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> positional;
  std::string platform_path, track_path;
  double rate = 500.0, check = -1.0;
  bool free_run = false, quiet = false;
  for (int k = 1; k < argc; ++k) {
    const std::string arg = argv[k];
    if (arg == "--platform" && k + 1 < argc) {
      platform_path = argv[++k];
    } else if (arg == "--rate" && k + 1 < argc) {
      rate = std::atof(argv[++k]);
    } else if (arg == "--check" && k + 1 < argc) {
      check = std::atof(argv[++k]);
    } else if (arg == "--track" && k + 1 < argc) {
      track_path = argv[++k];
    } else if (arg == "--free-run") {
      free_run = true;
    } else if (arg == "--quiet") {
      quiet = true;
    } else if (arg == "-h" || arg == "--help") {
      usage();
      return 0;
    } else if (!arg.empty() && arg[0] == '-') {
      std::fprintf(stderr, "control_loop: unknown option %s\n", arg.c_str());
      usage();
      return 2;
    } else {
      positional.push_back(arg);
    }
  }
  if (positional.size() != 2 || !(rate > 0)) {
    usage();
    return 2;
  }

  // --- set-up: may allocate ---------------------------------------------------------------------
  std::string error;
  ff::ParameterFile file;
  if (!ff::read_parameter_file(positional[0], &file, &error)) {
    std::fprintf(stderr, "error: %s\n", error.c_str());
    return 2;
  }
  ff::Geometry geometry = file.platform;
  if (!platform_path.empty()) {
    std::string name;
    if (!ff::read_platform_file(platform_path, &geometry, &name, &error)) {
      std::fprintf(stderr, "error: %s\n", error.c_str());
      return 2;
    }
  } else if (!file.has_platform) {
    std::fprintf(stderr, "warning: the parameter file names no platform: using the built-in prototype\n");
  }
  ff::Model model;
  if (ff::Model::create(geometry, file.parameters, file.extension, ff::Settings{}, &model) != ff::Status::ok) {
    std::fprintf(stderr, "error: invalid geometry or parameters\n");
    return 2;
  }
  Table table;
  if (!read_csv(positional[1], &table, &error)) {
    std::fprintf(stderr, "error: %s\n", error.c_str());
    return 2;
  }
  static const char* q_names[9] = {"v_x", "v_y", "omega", "alpha_l_dot", "alpha_r_dot",
                                   "beta_fl_dot", "beta_rl_dot", "beta_fr_dot", "beta_rr_dot"};
  static const char* m_names[4] = {"m_fl", "m_rl", "m_fr", "m_rr"};
  int col_t = table.index("t"), col_mode = table.index("mode"), col_segment = table.index("segment");
  int col_alpha[2] = {table.index("alpha_l"), table.index("alpha_r")};
  int col_q[9], col_m[4];
  bool has_m = true;
  for (int k = 0; k < 9; ++k) col_q[k] = table.index(q_names[k]);
  for (int k = 0; k < 4; ++k) has_m = has_m && (col_m[k] = table.index(m_names[k])) >= 0;
  if (col_t < 0 || col_mode < 0 || col_alpha[0] < 0 || col_alpha[1] < 0 ||
      std::any_of(col_q, col_q + 9, [](int c) { return c < 0; })) {
    std::fprintf(stderr, "error: %s: expected the columns of `agvdyn feedforward`: t, mode, alpha_l, alpha_r, "
                 "v_x, v_y, omega, alpha_l_dot, alpha_r_dot, beta_*_dot\n", positional[1].c_str());
    return 2;
  }
  const std::size_t n = table.rows.size();
  std::vector<double> t(n);
  std::vector<ff::Setpoint> setpoints(n);
  std::vector<ff::Vector4> reference(n, ff::Vector4::Zero());
  for (std::size_t i = 0; i < n; ++i) {
    const auto& row = table.rows[i];
    ff::Setpoint& sp = setpoints[i];
    ff::Vector9 q_dot;
    bool ok = to_number(row[col_t], &t[i]) && to_number(row[col_alpha[0]], &sp.alpha[0]) &&
              to_number(row[col_alpha[1]], &sp.alpha[1]) && ff::mode_from_label(row[col_mode].c_str(), &sp.mode);
    for (int k = 0; k < 9 && ok; ++k) ok = to_number(row[col_q[k]], &q_dot[k]);
    for (int k = 0; k < 4 && ok && has_m; ++k) ok = to_number(row[col_m[k]], &reference[i][k]);
    if (!ok) {
      std::fprintf(stderr, "error: %s: row %zu: expected numbers and a mode label\n", positional[1].c_str(), i + 2);
      return 2;
    }
    const ff::Status status = model.generalized_velocities(sp.mode, sp.alpha, q_dot, sp.s_dot);
    if (status != ff::Status::ok) {
      std::fprintf(stderr, "error: %s: row %zu: %s (mode %s, alpha = (%g, %g))\n", positional[1].c_str(), i + 2,
                   ff::to_string(status), ff::label(sp.mode), sp.alpha[0], sp.alpha[1]);
      return 2;
    }
  }
  // s_ddot: second-order differences of s_dot within each run of one mode and segment
  std::size_t start = 0;
  while (start < n) {
    std::size_t end = start + 1;
    while (end < n && setpoints[end].mode == setpoints[start].mode &&
           (col_segment < 0 || table.rows[end][col_segment] == table.rows[start][col_segment])) {
      ++end;
    }
    const std::size_t len = end - start;
    for (std::size_t i = start; i < end && len >= 3; ++i) {
      ff::Vector2 d;
      if (i == start) {
        d = (-3 * setpoints[i].s_dot + 4 * setpoints[i + 1].s_dot - setpoints[i + 2].s_dot) / (t[i + 2] - t[i]);
      } else if (i + 1 == end) {
        d = (3 * setpoints[i].s_dot - 4 * setpoints[i - 1].s_dot + setpoints[i - 2].s_dot) / (t[i] - t[i - 2]);
      } else {
        d = (setpoints[i + 1].s_dot - setpoints[i - 1].s_dot) / (t[i + 1] - t[i - 1]);
      }
      setpoints[i].s_ddot = d;
    }
    if (len == 2) {
      const ff::Vector2 d = (setpoints[start + 1].s_dot - setpoints[start].s_dot) / (t[start + 1] - t[start]);
      setpoints[start].s_ddot = setpoints[start + 1].s_ddot = d;
    }
    start = end;
  }
  // --track: the rows, the tracker and the per-tick buffers of its outputs
  const bool tracking = !track_path.empty();
  std::vector<ff::TrackerRow> rows;
  std::vector<int> row_log;
  std::vector<ff::Vector2> tracked_reference;
  ff::PayloadTracker tracker;
  if (tracking) {
    Table rt;
    if (!read_csv(track_path, &rt, &error)) {
      std::fprintf(stderr, "error: %s\n", error.c_str());
      return 2;
    }
    const int c_kind = rt.index("kind"), c_m = rt.index("phi_m"), c_c = rt.index("phi_C"), c_z = rt.index("z");
    const int c_log = rt.index("log"), c_rm = rt.index("m_ch"), c_rc = rt.index("C_ch");
    if (c_kind < 0 || c_m < 0 || c_c < 0 || c_z < 0) {
      std::fprintf(stderr, "error: %s: expected the columns kind, phi_m, phi_C, z\n", track_path.c_str());
      return 2;
    }
    for (std::size_t i = 0; i < rt.rows.size(); ++i) {
      const auto& row = rt.rows[i];
      double kind = 0, log = 0;
      ff::TrackerRow r;
      ff::Vector2 ref = ff::Vector2::Constant(std::nan(""));
      bool ok = to_number(row[c_kind], &kind) && to_number(row[c_m], &r.phi_m) && to_number(row[c_c], &r.phi_C) &&
                to_number(row[c_z], &r.z) && (c_log < 0 || to_number(row[c_log], &log));
      if (ok && c_rm >= 0 && c_rc >= 0) ok = to_number(row[c_rm], &ref[0]) && to_number(row[c_rc], &ref[1]);
      if (!ok) {
        std::fprintf(stderr, "error: %s: row %zu: expected numbers\n", track_path.c_str(), i + 2);
        return 2;
      }
      r.kind = static_cast<ff::RowKind>(static_cast<int>(kind));
      rows.push_back(r);
      row_log.push_back(static_cast<int>(log));
      tracked_reference.push_back(ref);
    }
    const ff::Parameters& p = file.parameters;
    if (ff::PayloadTracker::create(ff::Vector2(p.m_ch, p.C_ch), ff::Vector2::Zero(), 1.0 / rate, ff::TrackerSettings{},
                                   &tracker) != ff::Status::ok) {
      std::fprintf(stderr, "error: the tracker refuses m_ch = %g, C_ch = %g, dt = %g\n", p.m_ch, p.C_ch, 1.0 / rate);
      return 2;
    }
  }
  const std::size_t ticks = tracking ? rows.size() : n;
  std::vector<ff::Vector4> torques(ticks, ff::Vector4::Zero());
  std::vector<ff::Status> status(ticks, ff::Status::ok);
  std::vector<long long> compute_ns(ticks, 0), track_ns(tracking ? ticks : 0, 0);
  std::vector<ff::Vector2> tracked(tracking ? ticks : 0, ff::Vector2::Zero());
  std::vector<int> tracked_event(tracking ? ticks : 0, 0);
  std::vector<ff::Status> track_status(tracking ? ticks : 0, ff::Status::ok);
  ff::Model tracked_model = model;

  // --- the loop: no allocation, no I/O ----------------------------------------------------------
  using clock = std::chrono::steady_clock;
  const auto period = std::chrono::duration_cast<clock::duration>(std::chrono::duration<double>(1.0 / rate));
  const auto t_start = clock::now() + period;
  std::size_t late = 0;
  ff::TrackerOutput tracker_out;
  int log = tracking && ticks ? row_log[0] : 0;
  for (std::size_t k = 0; k < ticks; ++k) {
    const auto tick = t_start + static_cast<long long>(k) * period;
    if (!free_run) {
      if (clock::now() > tick) ++late;
      std::this_thread::sleep_until(tick);
    }
    const auto c0 = clock::now();
    if (tracking) {  // the tracker first, then the feed-forward with its estimates
      if (row_log[k] != log) {
        tracker.begin_log();
        log = row_log[k];
      }
      track_status[k] = tracker.update(rows[k], tracker_out);
      ff::Parameters p = model.parameters();
      p.m_ch = tracker_out.estimate[0];
      p.C_ch = tracker_out.estimate[1];
      if (model.with_parameters(p, &tracked_model) != ff::Status::ok) track_status[k] = ff::Status::invalid_model;
      tracked[k] = tracker_out.estimate;
      tracked_event[k] = tracker_out.event;
      const auto c1 = clock::now();
      track_ns[k] = std::chrono::duration_cast<std::chrono::nanoseconds>(c1 - c0).count();
      status[k] = tracked_model.feedforward(setpoints[k % n], torques[k]);
      compute_ns[k] = std::chrono::duration_cast<std::chrono::nanoseconds>(clock::now() - c1).count();
    } else {
      status[k] = model.feedforward(setpoints[k], torques[k]);
      const auto c1 = clock::now();
      compute_ns[k] = std::chrono::duration_cast<std::chrono::nanoseconds>(c1 - c0).count();
    }
  }

  // --- report -------------------------------------------------------------------------------------
  if (!quiet && tracking) {
    std::printf("t,mode,m_fl,m_rl,m_fr,m_rr,m_ch,C_ch,event\n");
    for (std::size_t k = 0; k < ticks; ++k) {
      const ff::Setpoint& sp = setpoints[k % n];
      std::printf("%.6f,%s,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%d\n", static_cast<double>(k) / rate, ff::label(sp.mode),
                  torques[k][0], torques[k][1], torques[k][2], torques[k][3], tracked[k][0], tracked[k][1],
                  tracked_event[k]);
    }
  } else if (!quiet) {
    std::printf("t,mode,m_fl,m_rl,m_fr,m_rr\n");
    for (std::size_t k = 0; k < n; ++k) {
      std::printf("%.6f,%s,%.17g,%.17g,%.17g,%.17g\n", t[k], ff::label(setpoints[k].mode), torques[k][0], torques[k][1],
                  torques[k][2], torques[k][3]);
    }
  }
  std::map<std::string, std::size_t> errors;
  for (std::size_t k = 0; k < ticks; ++k) {
    if (status[k] != ff::Status::ok) ++errors[ff::to_string(status[k])];
    if (tracking && track_status[k] != ff::Status::ok) ++errors[std::string("tracker ") + ff::to_string(track_status[k])];
  }
  std::vector<long long> sorted = compute_ns;
  std::sort(sorted.begin(), sorted.end());
  std::fprintf(stderr, "control_loop: %zu steps at %.0f Hz%s; feed-forward per call: median %lld ns, max %lld ns; "
               "late ticks %zu\n", ticks, rate, free_run ? " (free run)" : "", ticks ? sorted[ticks / 2] : 0LL,
               ticks ? sorted.back() : 0LL, late);
  for (const auto& [name, count] : errors) std::fprintf(stderr, "control_loop: %zu steps with %s\n", count, name.c_str());
  int rc = errors.empty() ? 0 : 1;
  if (tracking) {
    std::vector<long long> ts = track_ns;
    std::sort(ts.begin(), ts.end());
    const ff::Vector2 est = tracker.estimate(), sd = tracker.std();
    std::fprintf(stderr, "control_loop: tracker + model update per tick: median %lld ns, max %lld ns; %lld changes "
                 "detected; final m_ch %.2f +- %.2f kg, C_ch %.3f +- %.3f kg m^2\n", ticks ? ts[ticks / 2] : 0LL,
                 ticks ? ts.back() : 0LL, static_cast<long long>(tracker.event_count()), est[0], sd[0], est[1], sd[1]);
    double worst = -1;
    for (std::size_t k = 0; k < ticks; ++k) {
      if (std::isnan(tracked_reference[k][0])) continue;
      for (int i = 0; i < 2; ++i) {
        worst = std::max(worst, std::abs(tracked[k][i] - tracked_reference[k][i]) / std::abs(tracked_reference[k][i]));
      }
    }
    if (worst >= 0) {
      std::fprintf(stderr, "control_loop: largest relative deviation of the tracked m_ch, C_ch from the rows' "
                   "reference: %.3g\n", worst);
      if (check >= 0 && !(worst <= check)) {
        std::fprintf(stderr, "control_loop: deviation %.3g above --check %.3g\n", worst, check);
        rc = 1;
      }
    } else if (check >= 0) {
      std::fprintf(stderr, "control_loop: --check with --track needs the columns m_ch, C_ch in %s\n", track_path.c_str());
      rc = 1;
    }
  } else if (has_m) {
    double scale = 0, worst = 0;
    for (std::size_t k = 0; k < n; ++k) scale = std::max(scale, reference[k].cwiseAbs().maxCoeff());
    for (std::size_t k = 0; k < n; ++k) worst = std::max(worst, (torques[k] - reference[k]).cwiseAbs().maxCoeff());
    const double rel = scale > 0 ? worst / scale : worst;
    std::fprintf(stderr, "control_loop: largest deviation from the table's m_*: %.3g N m (%.3g of its largest torque "
                 "%.3g N m; s_ddot here is a difference quotient)\n", worst, rel, scale);
    if (check >= 0 && !(rel <= check)) {
      std::fprintf(stderr, "control_loop: deviation %.3g above --check %.3g\n", rel, check);
      rc = 1;
    }
  } else if (check >= 0) {
    std::fprintf(stderr, "control_loop: --check needs the columns m_fl, m_rl, m_fr, m_rr\n");
    rc = 1;
  }
  return rc;
}
