// pedalwave_plotdemo: writes one example of each plot kind of pedalwave::toolkit (and a CSV and
// a table) into a folder, from synthetic data, so the look of the plots can be checked by eye.
//
//   pedalwave_plotdemo [folder]        (default: plotdemo)
//
// The data are made up (a travelling wave on a 6-link chain, power-law error curves); they only
// exercise the plots. Exit status 0 when every file was written; 2 for a bad command line (an
// unknown option, more than one folder), 1 when a file cannot be written (toolkit/cli.hpp).
#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <iostream>
#include <numbers>
#include <string>
#include <vector>

#include "pedalwave/toolkit/cli.hpp"
#include "pedalwave/toolkit/toolkit.hpp"

namespace tk = pedalwave::toolkit;

namespace {

constexpr double kPi = std::numbers::pi;
constexpr int kLinks = 6;            // N
constexpr double kHalfLink = 0.045;  // l: half link length [m]

// The 2N+1 body points (tail tip, COM 1, joint 1, ..., COM N, head tip) of a chain whose link
// angles follow a travelling wave, resting on z = 0 and advancing with time.
tk::ShapeSnapshot body_at(double t) {
  tk::ShapeSnapshot s;
  s.t = t;
  double x = 0.04 * t;  // slow advance [m]
  double z = 0.0;
  s.x.push_back(x);
  s.z.push_back(z);
  for (int i = 0; i < kLinks; ++i) {
    const double theta = 0.55 * std::sin(2.0 * kPi * 0.5 * t - 1.1 * i);
    for (int half = 0; half < 2; ++half) {
      x += kHalfLink * std::cos(theta);
      z += kHalfLink * std::sin(theta);
      s.x.push_back(x);
      s.z.push_back(z);
    }
  }
  // rest the lowest point on the ground
  double zmin = s.z[0];
  for (double v : s.z) zmin = std::min(zmin, v);
  for (double& v : s.z) v -= zmin;
  return s;
}

void report(const tk::SaveResult& r) { std::cout << r.note << '\n'; }

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"pedalwave_plotdemo: one example of each plot kind (and a CSV and a table) from synthetic data"};
  std::string folder = "plotdemo";
  app.add_option("folder", folder, "output folder")->capture_default_str();
  if (const auto rc = tk::cli::parse(app, argc, argv, "pedalwave_plotdemo")) return *rc;
  try {
    const std::filesystem::path dir = folder;
    std::filesystem::create_directories(dir);

    // 1. Work-precision: error against cost for three integrators, 1 mm tolerance.
    {
      std::vector<tk::WorkPrecisionSeries> series;
      const struct {
        const char* name;
        double order;
        double c;
      } methods[] = {{"semi-implicit Euler", 1.0, 2e-4}, {"RK4", 4.0, 3e-9}, {"implicit midpoint", 2.0, 4e-6}};
      for (const auto& m : methods) {
        tk::WorkPrecisionSeries s{.label = m.name};
        for (int k = 0; k < 7; ++k) {
          const double dt = 1e-2 / std::pow(2.0, k);
          const double cost = 0.02 * (1e-2 / dt) * (m.order > 1 ? m.order / 2.0 : 1.0);
          s.cost.push_back(cost);
          s.error.push_back(m.c * std::pow(dt / 1e-3, m.order) * 1e-1 + 1e-12);
        }
        series.push_back(std::move(s));
      }
      auto fig = tk::work_precision_plot(series, {.title = "Work-precision (synthetic)",
                                                  .xlabel = "wall time per simulated second [s]",
                                                  .ylabel = "head-tip position error [m]",
                                                  .tolerance = 1e-3,
                                                  .tolerance_label = "1 mm"});
      report(fig.save(dir / "work_precision.svg"));
    }

    // 2. Snake shape snapshots over a stair and a low-friction patch.
    {
      std::vector<tk::ShapeSnapshot> snaps;
      for (int k = 0; k < 6; ++k) snaps.push_back(body_at(0.35 * k));
      tk::ShapePlotOptions opt;
      opt.title = "Body shape snapshots (synthetic pedal wave)";
      opt.patches.push_back({.x0 = 0.62, .x1 = 0.73, .z0 = 0.0, .z1 = 0.06, .label = "stair (6 cm)",
                             .fill = tk::Color{150, 150, 150}, .opacity = 0.55});
      opt.patches.push_back({.x0 = -0.05, .x1 = 0.25, .z0 = -0.012, .z1 = 0.0, .label = "low-\u03bc surface",
                             .fill = tk::Color{86, 180, 233}, .opacity = 0.6, .edge = std::nullopt});
      auto fig = tk::snake_shapes_plot(snaps, opt);
      report(fig.save(dir / "snake_shapes.svg"));

      // the same with a legend of times (few snapshots)
      std::vector<tk::ShapeSnapshot> few{body_at(0.0), body_at(0.5), body_at(1.0)};
      opt.title = "Body shape, legend of times";
      opt.time_legend = true;
      opt.patches.clear();
      report(tk::snake_shapes_plot(few, opt).save(dir / "snake_shapes_legend.svg"));
    }

    // 3. Paths of the head tip and the COM, x–z and x–t.
    std::vector<double> t;
    {
      tk::PathTrace head{.label = "head tip"}, com{.label = "COM"};
      for (int i = 0; i <= 400; ++i) {
        const double ti = 0.025 * i;
        const auto s = body_at(ti);
        double cx = 0.0, cz = 0.0;
        for (std::size_t k = 1; k < s.x.size(); k += 2) {
          cx += s.x[k] / kLinks;
          cz += s.z[k] / kLinks;
        }
        t.push_back(ti);
        head.t.push_back(ti), head.x.push_back(s.x.back()), head.z.push_back(s.z.back());
        com.t.push_back(ti), com.x.push_back(cx), com.z.push_back(cz);
      }
      const std::vector<tk::PathTrace> traces{head, com};
      report(tk::path_plot(traces, {.title = "Head tip and COM paths (x-z)", .ground_z = 0.0})
                 .save(dir / "paths_xz.svg"));
      report(tk::path_plot(traces, {.title = "Head tip and COM paths (x-t, z-t)", .view = tk::PathView::xt})
                 .save(dir / "paths_xt.svg"));
    }

    // 4. Stacked time series: joint torques with a gap (NaN) and an event mark.
    {
      std::vector<tk::SignalPanel> panels(3);
      panels[0].ylabel = "\u03c4 joints 1-3 [N\u00b7m]";
      panels[1].ylabel = "\u03c4 joints 4-5 [N\u00b7m]";
      panels[2].ylabel = "residual [rad]";
      panels[2].yscale = tk::Scale::log10;
      panels[0].hlines = {1.2, -1.2};
      for (int j = 0; j < 5; ++j) {
        tk::Signal s{.label = "joint " + std::to_string(j + 1)};
        for (double ti : t) {
          double v = (0.8 + 0.1 * j) * std::sin(2 * kPi * 0.5 * ti - 1.1 * j) + 0.15 * std::sin(2 * kPi * 3.0 * ti);
          if (j == 1 && ti > 4.0 && ti < 4.6) v = std::nan("");  // dropped samples
          s.y.push_back(v);
        }
        panels[j < 3 ? 0 : 1].signals.push_back(std::move(s));
      }
      tk::Signal r{.label = "|r|"};
      for (double ti : t) r.y.push_back(1e-4 * (1.0 + 0.8 * std::sin(5 * ti)) * (ti > 6.0 ? 300.0 : 1.0));
      panels[2].signals.push_back(std::move(r));
      panels[2].hlines = {5e-3};
      auto fig = tk::stacked_time_series(t, panels, {.title = "Joint torques and residual (synthetic)",
                                                     .marks = {{6.0, "head enters low-\u03bc patch"}}});
      report(fig.save(dir / "time_series.svg"));
    }

    // 5. A 2 × 2 figure showing the building blocks.
    {
      tk::Figure fig(2, 2, 1100, 750);
      fig.title("Building blocks");
      auto& a = fig.axes(0, 0);
      std::vector<double> x, y1, y2;
      for (int i = 0; i <= 60; ++i) {
        x.push_back(i * 0.1);
        y1.push_back(std::sin(i * 0.1));
        y2.push_back(std::cos(i * 0.1) * std::exp(-0.1 * i));
      }
      a.title("lines, dashes, reference lines").xlabel("t [s]").ylabel("y [-]");
      a.line(x, y1, {.label = "sin t"});
      a.line(x, y2, {.label = "damped cos", .dash = tk::Dash::dashed});
      a.hline(0.5, {.label = "limit 0.5"});
      a.vline(3.0, {.label = "t = 3 s"});
      auto& b = fig.axes(0, 1);
      b.title("scatter and markers").xlabel("x [mm]").ylabel("y [mm]");
      const tk::Marker ms[] = {tk::Marker::circle, tk::Marker::square, tk::Marker::triangle, tk::Marker::diamond,
                               tk::Marker::cross, tk::Marker::plus};
      for (int m = 0; m < 6; ++m) {
        std::vector<double> sx, sy;
        for (int i = 0; i < 8; ++i) {
          sx.push_back(i * 1.5);
          sy.push_back(m * 2.0 + 0.4 * std::sin(i + m));
        }
        b.scatter(sx, sy, {.label = "marker " + std::to_string(m), .marker = ms[m], .marker_px = 8});
      }
      b.legend(tk::LegendPos::none);
      auto& c = fig.axes(1, 0);
      c.title("semi-log, shaded span, text").xlabel("frequency [Hz]").ylabel("gain [-]").xscale(tk::Scale::log10);
      std::vector<double> f, g;
      for (int i = 0; i <= 80; ++i) {
        const double fi = std::pow(10.0, -1.0 + i * 0.05);
        f.push_back(fi);
        g.push_back(1.0 / std::sqrt(1.0 + std::pow(fi / 10.0, 4)));
      }
      c.rect(20.0, 200.0, -INFINITY, INFINITY, {.label = "stop band", .fill = tk::Color{230, 159, 0}, .opacity = 0.2});
      c.line(f, g, {.label = "2nd-order low pass"});
      c.text(10.0, 0.707, "corner 10 Hz", {.anchor = tk::Anchor::end, .dx_px = -6, .dy_px = -6});
      auto& d = fig.axes(1, 1);
      d.title("equal aspect, NaN gap").xlabel("x [m]").ylabel("z [m]").equal_aspect();
      std::vector<double> cx, cz;
      for (int i = 0; i <= 100; ++i) {
        const double th = 2 * kPi * i / 100.0;
        cx.push_back(i == 50 ? NAN : std::cos(th));
        cz.push_back(0.5 * std::sin(th));
      }
      d.line(cx, cz, {.label = "ellipse 2:1 with a gap", .width_px = 2.5});
      report(fig.save(dir / "building_blocks.svg"));
    }

    // 6. CSV and table.
    {
      const auto csv = dir / "signals.csv";
      {
        tk::CsvWriter w(csv, {"t", "x_head", "z_head"});
        w.comment("synthetic head-tip path, plotdemo");
        for (std::size_t i = 0; i < t.size(); i += 40) {
          const auto s = body_at(t[i]);
          w.row({t[i], s.x.back(), s.z.back()});
        }
        w.close();
      }
      const auto table = tk::CsvTable::read(csv);
      tk::Table out({"t [s]", "x head [m]", "z head [m]"});
      for (std::size_t i = 0; i < table.rows(); ++i) {
        out.add_row({tk::Table::num(table.column("t")[i]), tk::Table::num(table.column("x_head")[i]),
                     tk::Table::num(table.column("z_head")[i])});
      }
      std::cout << "wrote " << csv.string() << " (" << table.rows() << " rows); read back:\n" << out.to_text()
                << "\nas Markdown:\n" << out.to_markdown();
    }

    // 7. Progress bar over a short busy loop.
    {
      tk::Progress p("plotdemo busy loop", 200);
      volatile double sink = 0.0;
      for (int i = 0; i < 200; ++i) {
        for (int k = 0; k < 200000; ++k) sink = sink + std::sqrt(static_cast<double>(k));
        p.advance();
      }
      p.finish();
    }
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "pedalwave_plotdemo: error: " << e.what() << '\n';
    return tk::cli::kExitInternal;
  }
}
