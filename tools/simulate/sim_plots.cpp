// The figures of pedalwave_sim: a person should see the snake move without reading numbers.
#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

#include "pedalwave/toolkit/plots.hpp"
#include "sim_run.hpp"

namespace pedalwave::simulate {

namespace tk = pedalwave::toolkit;

namespace {

std::string fmt(double v, int precision = 3) {
  std::ostringstream os;
  os.precision(precision);
  os << v;
  return os.str();
}

std::string note(const tk::SaveResult& s) {
  return s.note.empty() ? s.svg.string() : s.note;
}

// Boxes, and the μ patches as strips just under the ground line (the last one up to x_hi).
std::vector<tk::Patch> scene_patches(const model::Scene& s, double x_hi) {
  std::vector<tk::Patch> out;
  if (!s.ground_on) return out;
  const double gz = s.ground.z;
  const auto& patches = s.ground.patches;
  for (std::size_t i = 0; i < patches.size(); ++i) {
    const double x1 = i + 1 < patches.size() ? patches[i + 1].x_begin : std::max(x_hi, patches[i].x_begin + 0.05);
    out.push_back({.x0 = patches[i].x_begin, .x1 = x1, .z0 = gz - 0.012, .z1 = gz,
                   .label = "μ = " + fmt(patches[i].mu, 2) + " from x = " + fmt(patches[i].x_begin, 2) + " m",
                   .fill = tk::Color{70, 130, 200}, .opacity = 0.55, .edge = std::nullopt});
  }
  for (std::size_t i = 0; i < s.boxes.size(); ++i) {
    const model::Box& b = s.boxes[i];
    out.push_back({.x0 = b.x_near, .x1 = b.x_near + b.width, .z0 = gz, .z1 = gz + b.height,
                   .label = i == 0 ? "box " + fmt(b.width * 100, 3) + " × " + fmt(b.height * 100, 3) + " cm"
                                   : std::string{},
                   .fill = tk::Color{160, 120, 80}, .opacity = 0.5, .edge = tk::Color{90, 60, 30}});
  }
  return out;
}

// Moving average over a window of `w` samples (centred; shorter at the ends).
std::vector<double> moving_average(const std::vector<double>& y, std::size_t w) {
  std::vector<double> out(y.size());
  if (w < 2) return y;
  const std::size_t h = w / 2;
  for (std::size_t i = 0; i < y.size(); ++i) {
    const std::size_t lo = i >= h ? i - h : 0, hi = std::min(y.size(), i + h + 1);
    double s = 0.0;
    for (std::size_t k = lo; k < hi; ++k) s += y[k];
    out[i] = s / static_cast<double>(hi - lo);
  }
  return out;
}

// Fixes a panel's y range to the 0.5 … 99.5 % quantiles of its samples (padded) when the full
// range is much wider (a start-up transient would otherwise flatten everything else). Returns
// whether it did.
bool robust_limits(tk::SignalPanel& p) {
  std::vector<double> all;
  for (const auto& sig : p.signals)
    for (double v : sig.y)
      if (std::isfinite(v)) all.push_back(v);
  if (all.size() < 20) return false;
  std::sort(all.begin(), all.end());
  const auto at = [&](double f) { return all[static_cast<std::size_t>(f * static_cast<double>(all.size() - 1))]; };
  const double lo = at(0.005), hi = at(0.995), span = std::max(hi - lo, 1e-9);
  if (all.front() >= lo - 0.5 * span && all.back() <= hi + 0.5 * span) return false;
  p.ylo = lo - 0.15 * span;
  p.yhi = hi + 0.15 * span;
  return true;
}

}  // namespace

std::vector<std::string> write_plots(const RunConfig& c, const RunResult& r) {
  std::vector<std::string> lines;
  if (r.t.empty()) return lines;
  const model::Scene& s = r.scene;
  const double ground = s.ground_on ? s.ground.z : tk::kNone;
  double x_hi = -1e300;
  for (const auto& bx : r.body_x)
    for (double x : bx) x_hi = std::max(x_hi, x);
  const auto patches = scene_patches(s, x_hi);
  const std::string title_tail = " — " + s.name + (c.loop.controller ? ", gait k_c = " + fmt(c.loop.k_c) : ", passive");

  // 1. Body shape snapshots, colour = time. With the gait running, the snapshots are a whole
  //    number of gait cycles apart: the same phase of the wave, so what changes is where the
  //    body is (the progress); a second figure shows the wave within the last cycle.
  const std::size_t n = r.t.size();
  const double dt = n > 1 ? r.t[1] - r.t[0] : 1.0;
  const double cycle = c.loop.controller && s.gait.omega != 0.0
                           ? 2.0 * std::numbers::pi / std::abs(s.gait.omega)
                           : tk::kNone;
  auto snapshot = [&](std::size_t i) {
    return tk::ShapeSnapshot{.t = r.t[i], .x = r.body_x[i], .z = r.body_z[i]};
  };
  {
    constexpr double want = 10.0;
    const double span = r.t.back() - r.t.front();
    double spacing = span / (want - 1.0);
    if (std::isfinite(cycle) && span >= cycle) spacing = cycle * std::max(1.0, std::round(spacing / cycle));
    const std::size_t stride = std::max<std::size_t>(1, static_cast<std::size_t>(std::lround(spacing / dt)));
    std::vector<tk::ShapeSnapshot> snaps;
    for (std::size_t i = 0; i < n; i += stride) snaps.push_back(snapshot(i));
    tk::ShapePlotOptions opt;
    opt.title = "Body every " + fmt(static_cast<double>(stride) * dt) + " s" +
                (std::isfinite(cycle) && span >= cycle ? " (same gait phase)" : "") + ", head tip ●" +
                title_tail;
    opt.ground_z = ground;
    opt.patches = patches;
    lines.push_back(note(tk::snake_shapes_plot(snaps, opt).save(c.out_dir / "shapes.svg")));
  }
  if (std::isfinite(cycle) && r.t.back() - r.t.front() >= cycle) {
    constexpr int kSnaps = 8;
    std::vector<tk::ShapeSnapshot> snaps;
    for (int k = 0; k < kSnaps; ++k) {
      const double tk_ = r.t.back() - cycle + cycle * k / kSnaps;
      const auto i = static_cast<std::size_t>(std::clamp<long>(std::lround((tk_ - r.t.front()) / dt), 0, static_cast<long>(n) - 1));
      snaps.push_back(snapshot(i));
    }
    tk::ShapePlotOptions opt;
    opt.title = "The pedal wave over the last gait cycle (" + fmt(snaps.front().t) + " … " +
                fmt(r.t.back()) + " s), head tip ●" + title_tail;
    opt.ground_z = ground;
    opt.patches = patches;
    lines.push_back(note(tk::snake_shapes_plot(snaps, opt).save(c.out_dir / "gait_cycle.svg")));
  }

  // 2. Head tip and COM paths (x–z), start ○ end □.
  {
    std::vector<tk::PathTrace> traces{{.label = "head tip", .t = r.t, .x = r.head_x, .z = r.head_z},
                                      {.label = "COM", .t = r.t, .x = r.com_x, .z = r.com_z}};
    tk::PathPlotOptions opt;
    opt.title = "Head tip and COM paths (start ○, end □)" + title_tail;
    opt.ground_z = ground;
    opt.patches = patches;
    auto fig = tk::path_plot(traces, opt);
    fig.axes().xlabel("x [m]").ylabel("z [m]");
    lines.push_back(note(fig.save(c.out_dir / "paths.svg")));
  }

  // 3. Joint torques: SEA torque and commanded torque, one panel per joint.
  {
    bool clipped = false;
    std::vector<tk::SignalPanel> panels;
    for (std::size_t j = 0; j < r.u.size(); ++j) {
      tk::SignalPanel p;
      p.ylabel = "joint " + std::to_string(j + 1) + " [N·m]";
      if (!r.tau_sea.empty())
        p.signals.push_back({.label = "τ_sea (spring)", .y = r.tau_sea[j], .color = tk::Color{31, 119, 180}});
      p.signals.push_back({.label = "u (commanded)", .y = r.u[j], .color = tk::colors::red,
                           .dash = tk::Dash::dashed, .width_px = 1.2});
      clipped |= robust_limits(p);
      panels.push_back(std::move(p));
    }
    tk::TimeSeriesOptions opt;
    opt.title = "Joint torques" + title_tail +
                (clipped ? " (start-up peaks off scale)" : "");
    opt.panel_height_px = 130.0;
    lines.push_back(note(tk::stacked_time_series(r.t, panels, opt).save(c.out_dir / "torques.svg")));
  }

  // 4. Progress: COM x over time, and the forward speed (instantaneous and over one gait cycle).
  {
    std::vector<double> x_cm(r.com_x.size()), v_cms(r.v_forward.size());
    for (std::size_t i = 0; i < x_cm.size(); ++i) x_cm[i] = 100.0 * (r.com_x[i] - r.com_x[0]);
    for (std::size_t i = 0; i < v_cms.size(); ++i) v_cms[i] = 100.0 * r.v_forward[i];
    tk::SignalPanel px{.ylabel = "COM x − x₀ [cm]", .signals = {{.label = "COM x", .y = x_cm}}};
    tk::SignalPanel pv{.ylabel = "forward speed [cm/s]"};
    pv.signals.push_back({.label = "instantaneous", .y = v_cms, .color = tk::Color{170, 170, 170}, .width_px = 1.0});
    if (std::isfinite(cycle)) {
      pv.signals.push_back({.label = "mean over one gait cycle (" + fmt(cycle) + " s)",
                            .y = moving_average(v_cms, static_cast<std::size_t>(std::lround(cycle / dt))),
                            .color = tk::Color{31, 119, 180}, .width_px = 2.0});
    }
    if (r.status == model::StepStatus::kOk)  // a failed run has no meaningful average speed
      pv.signals.push_back({.label = "average " + fmt(100.0 * r.avg_speed) + " cm/s",
                            .y = std::vector<double>(v_cms.size(), 100.0 * r.avg_speed),
                            .color = tk::colors::red, .dash = tk::Dash::dashed});
    std::vector<tk::SignalPanel> panels{px, pv};
    tk::TimeSeriesOptions opt;
    opt.title = "Forward progress" + title_tail;
    opt.panel_height_px = 220.0;
    lines.push_back(note(tk::stacked_time_series(r.t, panels, opt).save(c.out_dir / "speed.svg")));
  }
  return lines;
}

}  // namespace pedalwave::simulate
