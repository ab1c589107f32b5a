#include "pedalwave/toolkit/figures.hpp"

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <system_error>

namespace pedalwave::toolkit {

namespace fs = std::filesystem;

fs::path pick_figures_dir(const fs::path& source, const fs::path& installed) {
  std::error_code ec;
  return fs::is_directory(source, ec) ? source : installed;
}

fs::path figures_dir() { return pick_figures_dir(PEDALWAVE_FIGURES_DIR, PEDALWAVE_INSTALLED_FIGURES_DIR); }

std::string figure_python() {
  const char* env = std::getenv("PEDALWAVE_PYTHON");
  return env && *env ? std::string(env) : std::string("/usr/bin/python3");
}

namespace {

constexpr int kExecFailed = 127;  // the child could not start the interpreter

// Trims trailing newlines.
std::string trimmed(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
  return s;
}

}  // namespace

FigureOutcome draw_figures(const std::string& script, const std::vector<std::string>& args) {
  const fs::path path = figures_dir() / script;
  const std::string python = figure_python();
  std::error_code ec;
  if (!fs::is_regular_file(path, ec))
    return {FigureOutcome::Status::skipped, "figures skipped: the script " + path.string() + " is not there"};
  // -B: no __pycache__ beside the scripts (the source tree, or the installed folder).
  std::vector<std::string> argv_s{python, "-B", path.string()};
  argv_s.insert(argv_s.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : argv_s) argv.push_back(a.data());
  argv.push_back(nullptr);

  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0)
    return {FigureOutcome::Status::failed, std::string("figures FAILED: pipe: ") + std::strerror(errno)};
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(fds[0]);
    ::close(fds[1]);
    return {FigureOutcome::Status::failed, std::string("figures FAILED: fork: ") + std::strerror(errno)};
  }
  if (pid == 0) {  // child: stdout and stderr into the pipe, then the interpreter
    ::dup2(fds[1], STDOUT_FILENO);
    ::dup2(fds[1], STDERR_FILENO);
    ::execv(python.c_str(), argv.data());
    _exit(kExecFailed);
  }
  ::close(fds[1]);
  std::string out;
  char buf[4096];
  for (;;) {
    const ssize_t n = ::read(fds[0], buf, sizeof buf);
    if (n > 0) out.append(buf, static_cast<std::size_t>(n));
    else if (n == 0 || errno != EINTR) break;
  }
  ::close(fds[0]);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  out = trimmed(std::move(out));
  const int code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  if (code == 0) return {FigureOutcome::Status::drawn, out};
  if (code == kExecFailed && out.empty())
    return {FigureOutcome::Status::skipped, "figures skipped: cannot run the interpreter " + python +
                                                " (install python3-matplotlib, or set PEDALWAVE_PYTHON)"};
  if (code == 3) return {FigureOutcome::Status::skipped, out};
  return {FigureOutcome::Status::failed,
          "figures FAILED (" + path.filename().string() + " exit " + std::to_string(code) + "): " + out};
}

}  // namespace pedalwave::toolkit
