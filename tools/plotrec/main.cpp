// pedalwave_plot_recording: turns a monitor recording (pedalwave_monitor --record PREFIX.csv writes
// PREFIX.<topic>.csv, one file per topic) into the same plots as the simulation CLI: the snake's
// shape over time (measured joint angles α placed by the observer's predicted body pose θ_N, p_x,
// p_z), the predicted COM path, and stacked joint signals (α and α^d, SEA torque, command,
// residuals, forward speed, loop wake latency).
#include <CLI/CLI.hpp>

#include "pedalwave/toolkit/cli.hpp"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "pedalwave/model/kinematics.hpp"
#include "pedalwave/toolkit/toolkit.hpp"

namespace {

// A recorded topic: columns by name; text cells become NaN (the tool plots numbers only).
struct Table {
  std::string path;
  std::vector<std::string> names;
  std::vector<std::vector<double>> cols;
  const std::vector<double>& col(const std::string& n) const {
    for (std::size_t i = 0; i < names.size(); ++i)
      if (names[i] == n) return cols[i];
    throw std::runtime_error(path + ": no column '" + n + "' (is this a pedalwave_monitor recording?)");
  }
  bool has(const std::string& n) const {
    for (const auto& x : names)
      if (x == n) return true;
    return false;
  }
  std::size_t rows() const { return cols.empty() ? 0 : cols[0].size(); }
};

std::vector<std::string> split_csv(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted) {
      if (c == '"' && i + 1 < line.size() && line[i + 1] == '"') cur += '"', ++i;
      else if (c == '"') quoted = false;
      else cur += c;
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      out.push_back(cur);
      cur.clear();
    } else {
      cur += c;
    }
  }
  out.push_back(cur);
  return out;
}

Table read_table(const std::string& path, bool required) {
  Table t;
  t.path = path;
  std::ifstream in(path);
  if (!in) {
    if (required) throw std::runtime_error(path + ": cannot open (record with pedalwave_monitor --record PREFIX.csv)");
    return t;
  }
  std::string line;
  if (!std::getline(in, line)) throw std::runtime_error(path + ": empty file, expected a header line");
  t.names = split_csv(line);
  t.cols.assign(t.names.size(), {});
  std::size_t lineno = 1;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#') continue;
    const auto cells = split_csv(line);
    if (cells.size() != t.names.size()) {  // a line cut short (recording still being written)
      std::fprintf(stderr, "%s:%zu: %zu cells, the header names %zu: line skipped\n", path.c_str(),
                   lineno, cells.size(), t.names.size());
      continue;
    }
    for (std::size_t i = 0; i < cells.size(); ++i) {
      char* end = nullptr;
      const double v = std::strtod(cells[i].c_str(), &end);
      t.cols[i].push_back(end && *end == '\0' && !cells[i].empty() ? v : std::nan(""));
    }
  }
  return t;
}

int joints_of(const Table& t, const std::string& field) {
  int n = 0;
  while (t.has(field + "_" + std::to_string(n))) ++n;
  return n;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Plots of a pedalwave_monitor recording (same plots as pedalwave_sim)"};
  std::string prefix, out = "out/recording";
  double every = 1.0;
  app.add_option("recording", prefix, "the --record file name given to pedalwave_monitor (e.g. run.csv)")->required();
  app.add_option("--out", out, "folder for the plots");
  app.add_option("--every", every, "snapshot period of the shape plot [s]")->check(CLI::PositiveNumber);
  if (const auto rc = pedalwave::toolkit::cli::parse(app, argc, argv, "pedalwave_plot_recording")) return *rc;
  namespace tk = pedalwave::toolkit;
  namespace pm = pedalwave::model;
  try {
    std::string base = prefix;
    if (base.size() > 4 && base.substr(base.size() - 4) == ".csv") base.resize(base.size() - 4);
    const Table js = read_table(base + ".joint_state.csv", true);
    const Table cs = read_table(base + ".controller_state.csv", false);
    const Table os = read_table(base + ".observer_state.csv", false);
    const Table lt = read_table(base + ".loop_timing.csv", false);
    const Table rd = read_table(base + ".robot_description.csv", false);
    std::filesystem::create_directories(out);
    const int J = joints_of(js, "alpha");
    if (J < 1 || js.rows() < 2) throw std::runtime_error(js.path + ": no joint samples");
    // Time axis: the runtime's stamp, from the first sample.
    auto times = [](const Table& t) {
      std::vector<double> v;
      const auto& s = t.col("stamp_ns");
      for (double x : s) v.push_back((x - s.front()) * 1e-9);
      return v;
    };
    const std::vector<double> t = times(js);
    std::vector<tk::SignalPanel> panels;
    auto panel = [&](const Table& tab, const std::string& field, const std::string& label, const std::vector<double>& tt) {
      tk::SignalPanel p{.ylabel = label};
      for (int j = 0; j < joints_of(tab, field); ++j) {
        const auto& y = tab.col(field + "_" + std::to_string(j));
        std::vector<double> r;  // resample onto t (nearest earlier sample)
        std::size_t k = 0;
        for (double x : t) {
          while (k + 1 < tt.size() && tt[k + 1] <= x) ++k;
          r.push_back(tt.empty() ? std::nan("") : y[k]);
        }
        p.signals.push_back({.label = field + "_" + std::to_string(j + 1), .y = r});
      }
      return p;
    };
    panels.push_back(panel(js, "alpha", "α [rad] (measured)", t));
    if (cs.rows() > 0) panels.push_back(panel(cs, "alpha_d", "α^d [rad]", times(cs)));
    panels.push_back(panel(js, "tau_sea", "SEA torque [N·m]", t));
    if (cs.rows() > 0) panels.push_back(panel(cs, "u", "command u [N·m]", times(cs)));
    if (os.rows() > 0) panels.push_back(panel(os, "residual", "residual [N·m]", times(os)));
    auto st = tk::stacked_time_series(t, panels, {.title = "Recorded joint signals (" + base + ")"});
    const auto r1 = st.save(out + "/joint_signals.svg");
    std::printf("wrote %s%s\n", r1.svg.c_str(), r1.png ? " (+ .png)" : "");
    if (lt.rows() > 0) {
      const auto tl = times(lt);
      std::vector<double> lat;
      for (double x : lt.col("wake_latency_ns")) lat.push_back(x * 1e-3);
      std::vector<tk::SignalPanel> p{{.ylabel = "wake latency [µs]", .signals = {{.label = "latency", .y = lat}}}};
      const auto r = tk::stacked_time_series(tl, p, {.title = "Loop timing"}).save(out + "/loop_timing.svg");
      std::printf("wrote %s\n", r.svg.c_str());
    }
    // Shape and path: measured α placed by the observer's predicted body pose.
    if (os.rows() > 0 && os.has("theta_N")) {
      pm::Params prm = pm::paper_params(J + 1);
      if (rd.rows() > 0) prm.l = 0.5 * rd.col("link_length").back();
      prm.joints = pm::JointModel::kRigid;  // positions need only α, θ_N, p
      const pm::Model m(prm);
      pm::Data d(m);
      const auto to = times(os);
      const auto& seq_o = os.col("seq");
      const auto& seq_j = js.col("seq");
      std::vector<tk::ShapeSnapshot> snaps;
      std::vector<double> px, pz, pt;
      double next = 0.0;
      std::size_t k = 0;
      for (std::size_t i = 0; i < os.rows(); ++i) {
        while (k + 1 < js.rows() && seq_j[k + 1] <= seq_o[i]) ++k;  // joint sample of that cycle
        Eigen::VectorXd q(m.nq());
        for (int j = 0; j < J; ++j) q(j) = js.col("alpha_" + std::to_string(j))[k];
        q(m.i_theta_N()) = os.col("theta_N")[i];
        q(m.i_px()) = os.col("p_x")[i];
        q(m.i_pz()) = os.col("p_z")[i];
        if (!q.allFinite()) continue;
        pm::update_kinematics(m, d, q, Eigen::VectorXd());
        const pm::Vec2 c = pm::center_of_mass(m, d, q);
        pt.push_back(to[i]);
        px.push_back(c.x());
        pz.push_back(c.y());
        if (to[i] >= next) {
          tk::ShapeSnapshot s;
          s.t = to[i];
          for (int p = 0; p < m.points(); ++p) {
            const pm::Vec2 x = pm::point_position(m, d, q, p);
            s.x.push_back(x.x());
            s.z.push_back(x.y());
          }
          snaps.push_back(std::move(s));
          next = to[i] + every;
        }
      }
      const auto r2 = tk::snake_shapes_plot(snaps, {.title = "Snake shape (measured α, predicted body pose)"})
                          .save(out + "/snake_shapes.svg");
      std::vector<tk::PathTrace> tr{{.label = "COM (predicted)", .t = pt, .x = px, .z = pz}};
      const auto r3 = tk::path_plot(tr, {.title = "COM path", .view = tk::PathView::xt}).save(out + "/paths.svg");
      std::printf("wrote %s, %s\n", r2.svg.c_str(), r3.svg.c_str());
    } else {
      std::printf("no observer_state recording: shape and path plots skipped (they need the predicted body pose)\n");
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  }
  return 0;
}
