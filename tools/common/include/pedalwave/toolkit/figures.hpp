// The figures of the tools are drawn by Python scripts with matplotlib (tools/figures/*.py): a
// tool writes its data (CSV, and a JSON of what the figures need to know: titles, scene, events)
// and then runs the script of its figure family on that folder. A missing interpreter or
// matplotlib is not an error: the data stay written and the outcome says, in one line, that the
// figures were skipped and why.
//
//   const auto r = toolkit::draw_figures("simulate.py", {out_dir.string()});
//   std::cout << r.message << '\n';
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace pedalwave::toolkit {

// The folder of the figure scripts: the source tree's tools/figures while it exists (a build
// tree), else the installed <prefix>/share/pedalwave/figures (runtime/deploy/CMakeLists.txt).
[[nodiscard]] std::filesystem::path figures_dir();
// `source` when it is a folder, else `installed` (figures_dir() with the configured paths).
[[nodiscard]] std::filesystem::path pick_figures_dir(const std::filesystem::path& source,
                                                     const std::filesystem::path& installed);

// The interpreter the scripts run with: $PEDALWAVE_PYTHON when set and not empty, else
// /usr/bin/python3 (Debian's, which has python3-matplotlib; a user's PATH may put another first).
[[nodiscard]] std::string figure_python();

struct FigureOutcome {
  enum class Status {
    drawn,    // the script ran and wrote its figures
    skipped,  // no interpreter, no matplotlib/numpy, or no script: nothing drawn, data kept
    failed,   // the script ran and refused the data (a bug of the tool: the message says what)
  };
  Status status = Status::skipped;
  std::string message{};  // one or more lines for the user: the files written, or why not
};

// Runs `figure_python() -B figures_dir()/script args...` (fork/exec, no shell) and waits for it;
// the script's output becomes the message. Scripts exit 0 when done, 3 when matplotlib or numpy
// cannot be imported (skipped), 2 for bad data (failed: the file and the column named).
[[nodiscard]] FigureOutcome draw_figures(const std::string& script, const std::vector<std::string>& args);

}  // namespace pedalwave::toolkit
