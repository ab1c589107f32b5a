// The figures of pedalwave_sim: the data they need (body.csv, figures.json) beside trajectory.csv,
// drawn by tools/figures/simulate.py (matplotlib).
#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>

#include "pedalwave/toolkit/body_csv.hpp"
#include "pedalwave/toolkit/figures.hpp"
#include "pedalwave/toolkit/format.hpp"
#include "pedalwave/toolkit/json.hpp"
#include "sim_run.hpp"

namespace pedalwave::simulate {

namespace tk = pedalwave::toolkit;

namespace {

std::string fmt(double v, int precision = 3) { return tk::sig(v, precision); }

tk::Json scene_json(const model::Scene& s) {
  tk::Json boxes = tk::Json::array(), patches = tk::Json::array();
  for (const model::Box& b : s.boxes)
    boxes.push(tk::Json::object()
                   .set("x0", b.x_near).set("x1", b.x_near + b.width)
                   .set("z0", s.ground.z).set("z1", s.ground.z + b.height));
  for (const auto& p : s.ground.patches) patches.push(tk::Json::object().set("x_begin", p.x_begin).set("mu", p.mu));
  return tk::Json::object()
      .set("name", s.name)
      .set("ground_z", s.ground_on ? tk::Json(s.ground.z) : tk::Json())
      .set("boxes", std::move(boxes))
      .set("patches", std::move(patches));
}

}  // namespace

tk::FigureOutcome write_plots(const RunConfig& c, const RunResult& r) {
  if (r.t.empty()) return {tk::FigureOutcome::Status::skipped, "figures skipped: no samples"};
  // body.csv: the body points of every sample (the shapes), with the COM and the head tip.
  {
    tk::BodyPointsCsv csv(c.out_dir / "body.csv", {"t", "com_x", "com_z", "head_x", "head_z"}, r.body_x.front().size());
    csv.comment("pedalwave_sim, scene '" + r.scene.name + "': COM, head tip and the 2N+1 body points (tail tip first) [m]");
    for (std::size_t i = 0; i < r.t.size(); ++i)
      csv.row({r.t[i], r.com_x[i], r.com_z[i], r.head_x[i], r.head_z[i]}, r.body_x[i], r.body_z[i]);
    csv.close();
  }
  // figures.json: what the figures say about the run.
  {
    const model::Scene& s = r.scene;
    const bool gait = c.loop.controller && s.gait.omega != 0.0;
    tk::Json info = tk::Json::object();
    info.set("title", s.name + (c.loop.controller ? ", gait k_c = " + fmt(c.loop.k_c) : ", passive"));
    info.set("gait_period_s", gait ? tk::Json(2.0 * std::numbers::pi / std::abs(s.gait.omega)) : tk::Json());
    info.set("average_speed_m_s", r.status == model::StepStatus::kOk ? tk::Json(r.avg_speed) : tk::Json());
    info.set("scene", scene_json(s));
    std::ofstream f(c.out_dir / "figures.json");
    f << info.dump(2) << "\n";
    if (!f) throw std::runtime_error("cannot write " + (c.out_dir / "figures.json").string());
  }
  return tk::draw_figures("simulate.py", {c.out_dir.string()});
}

}  // namespace pedalwave::simulate
