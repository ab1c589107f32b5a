// Ready-made figures (tools/common/src/plots.cpp): what each draws and how it rejects bad input.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "pedalwave/toolkit/plots.hpp"
#include "svg_check.hpp"

namespace tk = pedalwave::toolkit;
using svgcheck::attr;
using svgcheck::elements;

namespace {

tk::ShapeSnapshot straight_body(double t, int links, double x0) {
  tk::ShapeSnapshot s;
  s.t = t;
  for (int i = 0; i <= 2 * links; ++i) {
    s.x.push_back(x0 + 0.05 * i);
    s.z.push_back(0.02 * std::sin(i + t));
  }
  return s;
}

}  // namespace

TEST(SnakeShapes, OnePolylinePerSnapshotColouredAlongTime) {
  std::vector<tk::ShapeSnapshot> snaps{straight_body(0.0, 6, 0.0), straight_body(1.0, 6, 0.1),
                                       straight_body(2.0, 6, 0.2)};
  tk::ShapePlotOptions opt;
  opt.patches.push_back({.x0 = 0.8, .x1 = 0.9, .z0 = 0.0, .z1 = 0.06, .label = "stair"});
  const auto fig = tk::snake_shapes_plot(snaps, opt);
  const std::string svg = fig.to_svg();
  ASSERT_EQ(svgcheck::well_formed(svg), "");
  const auto paths = elements(svg, "path", "class=\"series\"");
  ASSERT_EQ(paths.size(), 3u);
  // each body is one unbroken polyline; first and last snapshot take the colormap's ends
  for (const auto& p : paths) EXPECT_EQ(svgcheck::subpaths(attr(p.tag, "d")), 1u);
  EXPECT_NE(attr(paths[0].tag, "stroke"), attr(paths[2].tag, "stroke"));
  EXPECT_EQ(attr(paths[0].tag, "stroke"), tk::colormap(tk::Colormap::viridis, 0.0).hex());
  // joints/tips: indices 0, 2, ..., 12 → 7 markers per snapshot, plus the head tip
  std::size_t circles = elements(svg, "circle").size();
  EXPECT_EQ(circles, 3u * 7u + 3u + 2u);  // + 2 legend samples
  EXPECT_EQ(elements(svg, "rect", "class=\"colorbar\"").size(), 1u);
  // ground strip and stair patch, ground line
  EXPECT_EQ(elements(svg, "rect", "class=\"patch\"").size(), 2u);
  EXPECT_EQ(elements(svg, "line", "class=\"refline\"").size(), 1u);
  const auto legend = elements(svg, "text", "class=\"legend-label\"");
  ASSERT_EQ(legend.size(), 3u);
  EXPECT_EQ(legend[0].text, "stair");
}

TEST(SnakeShapes, TimeLegendInsteadOfColourBar) {
  std::vector<tk::ShapeSnapshot> snaps{straight_body(0.0, 3, 0.0), straight_body(0.5, 3, 0.1)};
  tk::ShapePlotOptions opt;
  opt.time_legend = true;
  const std::string svg = tk::snake_shapes_plot(snaps, opt).to_svg();
  EXPECT_EQ(elements(svg, "rect", "class=\"colorbar\"").size(), 0u);
  const auto legend = elements(svg, "text", "class=\"legend-label\"");
  ASSERT_GE(legend.size(), 2u);
  EXPECT_EQ(legend[0].text, "t = 0 s");
  EXPECT_EQ(legend[1].text, "t = 500 ms");
}

TEST(SnakeShapes, RejectsMismatchedSnapshot) {
  std::vector<tk::ShapeSnapshot> snaps{straight_body(0.0, 3, 0.0), straight_body(1.0, 3, 0.0)};
  snaps[1].z.pop_back();
  try {
    (void)tk::snake_shapes_plot(snaps);
    FAIL() << "accepted";
  } catch (const std::invalid_argument& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("snapshot 1"), std::string::npos) << m;
    EXPECT_NE(m.find("7 x values but 6 z values"), std::string::npos) << m;
  }
}

TEST(PathPlot, XzAndXtViews) {
  tk::PathTrace head{.label = "head tip"}, com{.label = "COM"};
  for (int i = 0; i < 50; ++i) {
    head.t.push_back(0.1 * i), head.x.push_back(0.01 * i), head.z.push_back(0.03 * std::abs(std::sin(0.3 * i)));
    com.t.push_back(0.1 * i), com.x.push_back(0.01 * i - 0.2), com.z.push_back(0.02);
  }
  const std::vector<tk::PathTrace> traces{head, com};
  const std::string xz = tk::path_plot(traces, {.ground_z = 0.0}).to_svg();
  ASSERT_EQ(svgcheck::well_formed(xz), "");
  EXPECT_EQ(elements(xz, "path", "class=\"series\"").size(), 2u);
  EXPECT_EQ(elements(xz, "rect", "class=\"frame\"").size(), 1u);
  const std::string xt = tk::path_plot(traces, {.view = tk::PathView::xt}).to_svg();
  ASSERT_EQ(svgcheck::well_formed(xt), "");
  EXPECT_EQ(elements(xt, "path", "class=\"series\"").size(), 4u);  // x(t) and z(t) per trace
  EXPECT_EQ(elements(xt, "rect", "class=\"frame\"").size(), 2u);
  // x–t needs times
  tk::PathTrace no_t{.label = "no time", .x = {0.0, 1.0}, .z = {0.0, 0.0}};
  const std::vector<tk::PathTrace> bad{no_t};
  EXPECT_NO_THROW((void)tk::path_plot(bad));
  try {
    (void)tk::path_plot(bad, {.view = tk::PathView::xt});
    FAIL() << "accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'no time'"), std::string::npos) << e.what();
  }
}

TEST(TimeSeries, StackedPanelsShareTimeAndMarks) {
  std::vector<double> t;
  for (int i = 0; i <= 100; ++i) t.push_back(0.01 * i);
  std::vector<tk::SignalPanel> panels(2);
  panels[0].ylabel = "tau [N m]";
  panels[1].ylabel = "err";
  for (int j = 0; j < 3; ++j) {
    tk::Signal s{.label = "joint " + std::to_string(j + 1)};
    for (double v : t) s.y.push_back(std::sin(v + j));
    panels[0].signals.push_back(s);
  }
  tk::Signal e{.label = "e"};
  for (double v : t) e.y.push_back(v);
  e.y[50] = NAN;
  panels[1].signals.push_back(e);
  const auto fig = tk::stacked_time_series(t, panels, {.title = "T", .marks = {{0.5, "event"}}});
  EXPECT_EQ(fig.rows(), 2);
  const std::string svg = fig.to_svg();
  ASSERT_EQ(svgcheck::well_formed(svg), "");
  const auto paths = elements(svg, "path", "class=\"series\"");
  ASSERT_EQ(paths.size(), 4u);
  EXPECT_EQ(svgcheck::subpaths(attr(paths[3].tag, "d")), 2u);  // the NaN splits "e"
  EXPECT_EQ(elements(svg, "line", "class=\"refline\"").size(), 2u);  // the mark in both panels
  std::size_t event_labels = 0;
  for (const auto& x : elements(svg, "text")) event_labels += x.text == "event" ? 1 : 0;
  EXPECT_EQ(event_labels, 1u);
  std::size_t time_labels = 0;
  for (const auto& x : elements(svg, "text")) time_labels += x.text == "time [s]" ? 1 : 0;
  EXPECT_EQ(time_labels, 1u);
}

TEST(TimeSeries, RejectsSignalOfWrongLength) {
  const std::vector<double> t{0, 1, 2};
  std::vector<tk::SignalPanel> panels(1);
  panels[0].ylabel = "p";
  panels[0].signals.push_back({.label = "short", .y = {1, 2}});
  try {
    (void)tk::stacked_time_series(t, panels);
    FAIL() << "accepted";
  } catch (const std::invalid_argument& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("'short'"), std::string::npos) << m;
    EXPECT_NE(m.find("2 samples but t has 3"), std::string::npos) << m;
  }
}

TEST(WorkPrecision, LogLogWithToleranceAndDistinctMarkers) {
  std::vector<tk::WorkPrecisionSeries> s{{"Euler", {1e-3, 1e-2, 1e-1}, {1e-2, 1e-3, 1e-4}},
                                         {"RK4", {2e-3, 2e-2, 2e-1}, {1e-5, 1e-9, 1e-13}}};
  const std::string svg = tk::work_precision_plot(s, {.tolerance = 1e-3, .tolerance_label = "1 mm"}).to_svg();
  ASSERT_EQ(svgcheck::well_formed(svg), "");
  EXPECT_EQ(elements(svg, "path", "class=\"series\"").size(), 2u);
  EXPECT_EQ(elements(svg, "line", "class=\"refline\"").size(), 1u);
  bool tol = false;
  for (const auto& x : elements(svg, "text")) tol = tol || x.text == "1 mm";
  EXPECT_TRUE(tol);
  EXPECT_GE(elements(svg, "line", "class=\"xminor\"").size(), 8u);
  // Euler markers are circles, RK4 squares (3 each + 1 legend sample each)
  EXPECT_EQ(elements(svg, "circle").size(), 4u);
  EXPECT_EQ(elements(svg, "rect", "width=\"7.04\"").size(), 4u);
}
