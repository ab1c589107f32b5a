#include "pedalwave/toolkit/plots.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "pedalwave/toolkit/ticks.hpp"

namespace pedalwave::toolkit {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr Color kGroundFill{222, 208, 186};

struct Span2 {
  double lo = kInf, hi = -kInf;
  void add(double v) {
    if (!std::isfinite(v)) return;
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  [[nodiscard]] double size() const { return hi > lo ? hi - lo : 0.0; }
};

void draw_ground_and_patches(Axes& ax, double ground_z, const std::vector<Patch>& patches) {
  if (std::isfinite(ground_z)) {
    ax.rect(-kInf, kInf, -kInf, ground_z, {.label = "", .fill = kGroundFill, .opacity = 0.7, .edge = std::nullopt});
  }
  for (const auto& p : patches) {
    ax.rect(p.x0, p.x1, p.z0, p.z1,
            {.label = p.label, .fill = p.fill, .opacity = p.opacity, .edge = p.edge, .edge_px = 1.0});
  }
  if (std::isfinite(ground_z)) {
    ax.hline(ground_z, {.label = "", .color = colors::ground, .width_px = 1.6, .dash = Dash::solid});
  }
}

std::string time_text(double t) { return "t = " + format_si(t, "s", 3); }

}  // namespace

Figure snake_shapes_plot(std::span<const ShapeSnapshot> snapshots, const ShapePlotOptions& opt) {
  // Validate and find the extent of everything drawn.
  Span2 xs, zs, ts;
  for (std::size_t k = 0; k < snapshots.size(); ++k) {
    const auto& s = snapshots[k];
    if (s.x.size() != s.z.size()) {
      throw std::invalid_argument("snake_shapes_plot: snapshot " + std::to_string(k) + " (t = " +
                                  format_si(s.t, "s") + ") has " + std::to_string(s.x.size()) +
                                  " x values but " + std::to_string(s.z.size()) + " z values");
    }
    if (s.x.size() < 2) {
      throw std::invalid_argument("snake_shapes_plot: snapshot " + std::to_string(k) + " has " +
                                  std::to_string(s.x.size()) +
                                  " points, expected the 2N+1 body points (at least 2)");
    }
    for (double v : s.x) xs.add(v);
    for (double v : s.z) zs.add(v);
    ts.add(s.t);
  }
  for (const auto& p : opt.patches) {
    xs.add(p.x0);
    xs.add(p.x1);
    zs.add(p.z0);
    zs.add(p.z1);
  }
  zs.add(opt.ground_z);

  // Canvas height from the data's aspect so an equal-aspect body fills the width.
  const double plot_w = opt.width_px - 330.0;  // minus axis labels, colour bar and legend
  double height = 600.0;
  if (opt.equal_aspect && xs.size() > 0.0) {
    height = plot_w * (zs.size() * 1.2 + 1e-9) / (xs.size() * 1.08) + 150.0;
  }
  height = std::clamp(height, 320.0, 900.0);
  Figure fig(1, 1, opt.width_px, height);
  fig.title(opt.title);
  Axes& ax = fig.axes();
  ax.xlabel("x [m]").ylabel("z [m]").ymargin(0.1).legend(LegendPos::outside_right);
  if (opt.equal_aspect) ax.equal_aspect();
  // Ground strip of 12 % of the height below the lowest thing drawn; free room goes above.
  if (std::isfinite(opt.ground_z) && zs.size() > 0.0) ax.ylim(zs.lo - 0.12 * zs.size(), kNone);
  draw_ground_and_patches(ax, opt.ground_z, opt.patches);

  const double t0 = ts.lo, t1 = ts.hi;
  auto tfrac = [&](double t) { return (t1 > t0) ? (t - t0) / (t1 - t0) : 1.0; };
  const bool legend_times = opt.time_legend || snapshots.size() == 1;
  for (const auto& s : snapshots) {
    // A dark-ended colormap: keep the brightest end slightly darker so it stays visible on white.
    const Color c = colormap(opt.map, 0.92 * tfrac(s.t));
    ax.line(s.x, s.z, {.label = legend_times ? time_text(s.t) : "", .color = c, .width_px = 2.2});
    if (opt.joint_stride > 0) {
      std::vector<double> jx, jz;
      for (std::size_t i = 0; i < s.x.size(); i += opt.joint_stride) {
        jx.push_back(s.x[i]);
        jz.push_back(s.z[i]);
      }
      ax.scatter(jx, jz, {.label = "", .color = c, .marker = Marker::circle, .marker_px = 5.5});
    }
    const std::vector<double> hx{s.x.back()}, hz{s.z.back()};
    ax.scatter(hx, hz, {.label = "", .color = c, .marker = Marker::circle, .marker_px = 9.0});
  }
  // legend keys for the markers (no data: legend only)
  const std::vector<double> none;
  if (opt.joint_stride > 0 && !snapshots.empty()) {
    ax.scatter(none, none, {.label = "joints / tips", .color = colors::dark_gray, .marker = Marker::circle, .marker_px = 5.5});
  }
  if (!snapshots.empty()) {
    ax.scatter(none, none, {.label = "head tip", .color = colors::dark_gray, .marker = Marker::circle, .marker_px = 9.0});
  }
  if (!legend_times && !snapshots.empty()) ax.colorbar(opt.map, t0, t1 > t0 ? t1 : t0 + 1e-9, "time [s]");
  if (snapshots.empty()) ax.text(0.5, 0.5, "no snapshots", {.anchor = Anchor::middle});
  return fig;
}

Figure path_plot(std::span<const PathTrace> traces, const PathPlotOptions& opt) {
  for (const auto& tr : traces) {
    const bool need_t = opt.view == PathView::xt;
    if (tr.x.size() != tr.z.size() || (need_t && tr.t.size() != tr.x.size()) ||
        (!tr.t.empty() && tr.t.size() != tr.x.size())) {
      throw std::invalid_argument("path_plot: trace '" + tr.label + "' has " + std::to_string(tr.t.size()) +
                                  " t, " + std::to_string(tr.x.size()) + " x and " + std::to_string(tr.z.size()) +
                                  " z values; expected equal lengths" + (need_t ? " (t is required for the x-t view)" : ""));
    }
  }
  if (opt.view == PathView::xz) {
    Figure fig(1, 1, opt.width_px, opt.height_px);
    fig.title(opt.title);
    Axes& ax = fig.axes();
    ax.xlabel("x [m]").ylabel("z [m]").ymargin(0.1);
    if (opt.equal_aspect) ax.equal_aspect();
    draw_ground_and_patches(ax, opt.ground_z, opt.patches);
    for (std::size_t i = 0; i < traces.size(); ++i) {
      const auto& tr = traces[i];
      const Color c = cycle_color(i);
      ax.line(tr.x, tr.z, {.label = tr.label, .color = c, .width_px = 2.0});
      if (!tr.x.empty()) {
        const std::vector<double> sx{tr.x.front()}, sz{tr.z.front()}, ex{tr.x.back()}, ez{tr.z.back()};
        ax.scatter(sx, sz, {.color = c, .marker = Marker::circle, .marker_px = 8.0, .hollow_markers = true});
        ax.scatter(ex, ez, {.color = c, .marker = Marker::square, .marker_px = 8.0});
      }
    }
    if (!traces.empty()) {
      const std::vector<double> none;
      ax.scatter(none, none, {.label = "start", .color = colors::dark_gray, .marker = Marker::circle, .marker_px = 8.0, .hollow_markers = true});
      ax.scatter(none, none, {.label = "end", .color = colors::dark_gray, .marker = Marker::square, .marker_px = 8.0});
    }
    return fig;
  }
  Figure fig(2, 1, opt.width_px, opt.height_px);
  fig.title(opt.title).share_x();
  Axes& top = fig.axes(0, 0);
  Axes& bottom = fig.axes(1, 0);
  top.ylabel("x [m]").xmargin(0.0);
  bottom.ylabel("z [m]").xlabel("time [s]").xmargin(0.0);
  for (std::size_t i = 0; i < traces.size(); ++i) {
    const auto& tr = traces[i];
    const Color c = cycle_color(i);
    top.line(tr.t, tr.x, {.label = tr.label, .color = c, .width_px = 1.8});
    bottom.line(tr.t, tr.z, {.label = tr.label, .color = c, .width_px = 1.8});
  }
  bottom.legend(LegendPos::none);
  return fig;
}

Figure stacked_time_series(std::span<const double> t, std::span<const SignalPanel> panels,
                           const TimeSeriesOptions& opt) {
  const int rows = std::max<int>(1, static_cast<int>(panels.size()));
  const double top = opt.title.empty() ? 0.0 : 40.0;
  const double height = std::clamp(opt.panel_height_px * rows + top + 40.0, 200.0, 20000.0);
  Figure fig(rows, 1, opt.width_px, height);
  if (!opt.title.empty()) fig.title(opt.title);
  fig.share_x();
  for (std::size_t pi = 0; pi < panels.size(); ++pi) {
    const auto& pn = panels[pi];
    Axes& ax = fig.axes(static_cast<int>(pi), 0);
    ax.ylabel(pn.ylabel).xmargin(0.0).yscale(pn.yscale).ylim(pn.ylo, pn.yhi).legend(opt.legend);
    if (pi + 1 == panels.size()) ax.xlabel(opt.xlabel);
    for (double h : pn.hlines) ax.hline(h);
    for (const auto& m : opt.marks) {
      ax.vline(m.t, {.label = pi == 0 ? m.label : "", .color = Color{170, 50, 50}, .width_px = 1.2, .dash = Dash::dash_dot});
    }
    for (const auto& s : pn.signals) {
      if (s.y.size() != t.size()) {
        throw std::invalid_argument("stacked_time_series: panel '" + pn.ylabel + "' signal '" + s.label +
                                    "' has " + std::to_string(s.y.size()) + " samples but t has " +
                                    std::to_string(t.size()));
      }
      ax.line(t, s.y, {.label = s.label, .color = s.color, .width_px = s.width_px, .dash = s.dash});
    }
  }
  if (panels.empty()) fig.axes().xlabel(opt.xlabel);
  return fig;
}

Figure work_precision_plot(std::span<const WorkPrecisionSeries> series, const WorkPrecisionOptions& opt) {
  Figure fig(1, 1, opt.width_px, opt.height_px);
  fig.title(opt.title);
  Axes& ax = fig.axes();
  ax.xscale(Scale::log10).yscale(Scale::log10).xlabel(opt.xlabel).ylabel(opt.ylabel);
  static constexpr Marker kMarkers[] = {Marker::circle, Marker::square, Marker::triangle,
                                        Marker::diamond, Marker::cross, Marker::plus};
  for (std::size_t i = 0; i < series.size(); ++i) {
    const auto& s = series[i];
    ax.line(s.cost, s.error,
            {.label = s.label, .color = cycle_color(i), .width_px = 1.8,
             .marker = kMarkers[i % std::size(kMarkers)], .marker_px = 8.0});
  }
  if (std::isfinite(opt.tolerance)) {
    ax.hline(opt.tolerance, {.label = opt.tolerance_label, .color = Color{170, 50, 50}, .width_px = 1.3});
  }
  return fig;
}

}  // namespace pedalwave::toolkit
