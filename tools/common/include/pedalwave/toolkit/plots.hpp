// Ready-made figures the tools call: snake shape snapshots, head/COM paths, stacked time series
// and work-precision (error versus cost) plots. Each returns a Figure the caller may adjust
// further (fig.axes(...)) before fig.save(...).
#pragma once

#include <cstddef>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "pedalwave/toolkit/figure.hpp"

namespace pedalwave::toolkit {

inline constexpr double kNone = std::numeric_limits<double>::quiet_NaN();

// A box or surface patch in the XZ plane (a stair, a low-friction strip drawn just below the
// ground line, ...).
struct Patch {
  double x0 = 0.0, x1 = 0.0;          // horizontal extent [m]
  double z0 = 0.0, z1 = 0.0;          // vertical extent [m]
  std::string label{};                  // legend text; empty = not in the legend
  Color fill = Color{150, 150, 150};  // fill colour
  double opacity = 0.45;              // fill opacity [0..1]
  std::optional<Color> edge = Color{90, 90, 90};  // outline; none = no outline
};

// ---- Snake shape snapshots ----------------------------------------------------------------------

// The body at one instant: the 2N+1 points along it, in order from the tail tip to the head tip
// (tail tip, link 1 COM, joint 1, link 2 COM, ..., link N COM, head tip), so even indices are the
// tips and joints and odd indices the link COMs (model-spec §1, §6).
struct ShapeSnapshot {
  double t = 0.0;          // time of the snapshot [s]
  std::vector<double> x{};   // horizontal position of each point [m], (2N+1)
  std::vector<double> z{};   // vertical position of each point [m], (2N+1)
};

struct ShapePlotOptions {
  std::string title = "Body shape";
  double width_px = 1000.0;          // canvas width; the height follows the data's aspect
  double ground_z = 0.0;             // ground height [m]; NaN = no ground drawn
  std::vector<Patch> patches{};        // obstacles and surface patches
  std::size_t joint_stride = 2;      // mark points whose index is a multiple of this (2: tips
                                     // and joints); 0 = no joint markers
  bool equal_aspect = true;          // true shape (1 m on x = 1 m on z)
  bool time_legend = false;          // a legend of times instead of the colour bar
  Colormap map = Colormap::viridis;  // colour along time
};

// Each snapshot as a polyline (colour = its time on `map`), joints marked, head tip marked by a
// larger dot, ground line (with a shaded ground strip), patches, and a colour bar of time (or a
// legend). Throws std::invalid_argument naming the snapshot when x and z sizes differ or a
// snapshot has fewer than 2 points; an empty list gives an empty, labelled panel.
[[nodiscard]] Figure snake_shapes_plot(std::span<const ShapeSnapshot> snapshots,
                                       const ShapePlotOptions& options = {});

// ---- Paths --------------------------------------------------------------------------------------

// A point's trajectory (head tip, COM, ...).
struct PathTrace {
  std::string label{};       // legend text
  std::vector<double> t{};   // time [s], (n) (may be empty for the x–z view)
  std::vector<double> x{};   // horizontal position [m], (n)
  std::vector<double> z{};   // vertical position [m], (n)
};

enum class PathView {
  xz,  // z against x, start marked by a circle and end by a square
  xt,  // two stacked panels sharing time: x(t) above, z(t) below
};

struct PathPlotOptions {
  std::string title = "Paths";
  PathView view = PathView::xz;
  double width_px = 1000.0;
  double height_px = 600.0;
  double ground_z = kNone;        // ground height for the x–z view [m]; NaN = none
  std::vector<Patch> patches{};     // drawn in the x–z view
  bool equal_aspect = false;      // x–z view only
};

// Throws std::invalid_argument naming the trace when its sizes differ (t is required for xt).
[[nodiscard]] Figure path_plot(std::span<const PathTrace> traces, const PathPlotOptions& options = {});

// ---- Stacked time series -------------------------------------------------------------------------

struct Signal {
  std::string label{};              // legend text
  std::vector<double> y{};          // samples at the shared times [unit of the panel], (n)
  std::optional<Color> color{};     // default: the colour cycle
  Dash dash = Dash::solid;
  double width_px = 1.5;
};

struct SignalPanel {
  std::string ylabel{};             // e.g. "τ_s [N·m]"
  std::vector<Signal> signals{};
  double ylo = kNone, yhi = kNone;  // fixed y limits; NaN = automatic
  Scale yscale = Scale::linear;
  std::vector<double> hlines{};     // dashed reference levels (limits, tolerances)
};

// A time marked in every panel (e.g. "head enters low-μ patch"); the label shows in the top panel.
struct TimeMark {
  double t = 0.0;                 // [s]
  std::string label{};
};

struct TimeSeriesOptions {
  std::string title{};
  std::string xlabel = "time [s]";
  double width_px = 1000.0;
  double panel_height_px = 190.0;  // height of each panel; the canvas height follows
  std::vector<TimeMark> marks{};
  LegendPos legend = LegendPos::outside_right;  // dense signals leave no free corner
};

// One panel per SignalPanel, stacked top to bottom, sharing the time axis (tight, no margin).
// Throws std::invalid_argument naming panel and signal when a signal's length differs from t's.
[[nodiscard]] Figure stacked_time_series(std::span<const double> t,
                                         std::span<const SignalPanel> panels,
                                         const TimeSeriesOptions& options = {});

// ---- Work-precision ------------------------------------------------------------------------------

struct WorkPrecisionSeries {
  std::string label{};              // method, e.g. "RK4"
  std::vector<double> cost{};       // cost of each run (wall time [s], evaluations, ...), (n)
  std::vector<double> error{};      // error of each run against the reference, (n)
};

struct WorkPrecisionOptions {
  std::string title = "Work-precision";
  std::string xlabel = "wall time [s]";
  std::string ylabel = "error [m]";
  double tolerance = kNone;       // horizontal reference line; NaN = none
  std::string tolerance_label{};    // e.g. "1 mm"
  double width_px = 1000.0;
  double height_px = 600.0;
};

// Log–log: error against cost, one line with markers per method (distinct marker shapes).
[[nodiscard]] Figure work_precision_plot(std::span<const WorkPrecisionSeries> series,
                                         const WorkPrecisionOptions& options = {});

}  // namespace pedalwave::toolkit
