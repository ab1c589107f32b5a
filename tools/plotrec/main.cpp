// pedalwave_plot_recording: turns a monitor recording (pedalwave_monitor --record PREFIX.csv writes
// PREFIX.<topic>.csv, one file per topic) into the same plots as the simulation CLI. It computes
// the body (measured joint angles α placed by the observer's predicted body pose θ_N, p_x, p_z)
// into OUT/body.csv; tools/figures/recording.py draws the snake's shape over time, the predicted
// COM path, and stacked joint signals (α and α^d, SEA torque, command, residuals, loop wake
// latency) from the topic files and body.csv.
#include <CLI/CLI.hpp>

#include "pedalwave/toolkit/body_csv.hpp"
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
#include "pedalwave/toolkit/csv.hpp"
#include "pedalwave/toolkit/figures.hpp"

namespace {

using Table = pedalwave::toolkit::CsvTable;

// A recorded topic: columns by name; text cells become NaN (the tool plots numbers only), a line
// cut short (the recording still being written) is skipped with a note. A missing optional topic
// is an empty table.
Table read_table(const std::string& path, bool required) {
  if (!std::filesystem::exists(path)) {
    if (required) throw std::runtime_error(path + ": cannot open (record with pedalwave_monitor --record PREFIX.csv)");
    return Table::parse("x\n", path);
  }
  Table t = Table::read(path, {.text_as_nan = true, .skip_ragged = true});
  for (const std::string& s : t.skipped()) std::fprintf(stderr, "%s\n", s.c_str());
  return t;
}

// Joint columns <field>_1, <field>_2, … (1-based) in the recording.
int joints_of(const Table& t, const std::string& field) {
  int n = 0;
  while (t.has(field + "_" + std::to_string(n + 1))) ++n;
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
    const Table os = read_table(base + ".observer_state.csv", false);
    const Table rd = read_table(base + ".robot_description.csv", false);
    std::filesystem::create_directories(out);
    const int J = joints_of(js, "alpha");
    if (J < 1 || js.rows() < 2) throw std::runtime_error(js.source() + ": no joint samples");
    // Time axis: the runtime's stamp, from the joint samples' first (the figures use the same).
    const double t0 = js.column("stamp_ns").front();
    // Shape and path: measured α placed by the observer's predicted body pose.
    if (os.rows() > 0 && os.has("theta_N")) {
      pm::Params prm = pm::paper_params(J + 1);
      if (rd.rows() > 0) prm.l = 0.5 * rd.column("link_length").back();
      prm.joints = pm::JointModel::kRigid;  // positions need only α, θ_N, p
      const pm::Model m(prm);
      pm::Data d(m);
      const auto& stamp_o = os.column("stamp_ns");
      const auto& seq_o = os.column("seq");
      const auto& seq_j = js.column("seq");
      const auto P = static_cast<std::size_t>(m.points());
      tk::BodyPointsCsv body(out + "/body.csv", {"t", "com_x", "com_z", "head_x", "head_z"}, P);
      body.comment("measured α placed by the observer's predicted body pose (θ_N, p_x, p_z) of " + base);
      std::vector<double> x(P), z(P);
      std::size_t k = 0;
      for (std::size_t i = 0; i < os.rows(); ++i) {
        while (k + 1 < js.rows() && seq_j[k + 1] <= seq_o[i]) ++k;  // joint sample of that cycle
        Eigen::VectorXd q(m.nq());
        for (int j = 0; j < J; ++j) q(j) = js.column("alpha_" + std::to_string(j + 1))[k];
        q(m.i_theta_N()) = os.column("theta_N")[i];
        q(m.i_px()) = os.column("p_x")[i];
        q(m.i_pz()) = os.column("p_z")[i];
        if (!q.allFinite()) continue;
        pm::update_kinematics(m, d, q, Eigen::VectorXd());
        const pm::Vec2 c = pm::center_of_mass(m, d, q);
        const pm::Vec2 h = pm::point_position(m, d, q, m.point_head());
        for (std::size_t p = 0; p < P; ++p) {
          const pm::Vec2 pt = pm::point_position(m, d, q, static_cast<int>(p));
          x[p] = pt.x();
          z[p] = pt.y();
        }
        body.row({(stamp_o[i] - t0) * 1e-9, c.x(), c.y(), h.x(), h.y()}, x, z);
      }
      body.close();
    } else {
      std::printf("no observer_state recording: shape and path plots skipped (they need the predicted body pose)\n");
      std::filesystem::remove(out + "/body.csv");
    }
    // The figures (tools/figures/recording.py) from the recording's topic files and body.csv.
    std::fflush(stdout);
    const tk::FigureOutcome r = tk::draw_figures(
        "recording.py", {base, out, "--every", tk::format_double(every)});
    std::fprintf(r.status == tk::FigureOutcome::Status::drawn ? stdout : stderr, "%s\n", r.message.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  }
  return 0;
}
