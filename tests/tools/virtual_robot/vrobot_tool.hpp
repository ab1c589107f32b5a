// pedalwave_virtual_robot (PEDALWAVE_VROBOT_EXE) as a child process for the tests that drive the
// tool from its command line (vrobot_cli_test, vrobot_xseries_test).
#pragma once

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <string>
#include <vector>

#include "walk_rig.hpp"

namespace pedalwave::test {

// The tool as a child process with stdout+stderr on a pipe.
class Tool {
 public:
  explicit Tool(std::vector<std::string> args) {
    args.insert(args.begin(), PEDALWAVE_VROBOT_EXE);
    int p[2];
    if (::pipe2(p, O_CLOEXEC) != 0) return;
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    const pid_t parent = ::getpid();
    pid_ = ::fork();
    if (pid_ == 0) {
      if (::prctl(PR_SET_PDEATHSIG, SIGKILL) != 0 || ::getppid() != parent) ::_exit(126);
      ::dup2(p[1], STDOUT_FILENO);
      ::dup2(p[1], STDERR_FILENO);
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    ::close(p[1]);
    out_ = p[0];
  }
  ~Tool() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
    if (out_ >= 0) ::close(out_);
  }
  // Reads until `needle` appears in the output or the tool closes it (EOF) / timeout_s passes.
  bool read_until(const std::string& needle, double timeout_s) {
    const std::int64_t end = pedalwave::monotonic_ns() + static_cast<std::int64_t>(timeout_s * 1e9);
    while (text.find(needle) == std::string::npos) {
      const std::int64_t left_ms = (end - pedalwave::monotonic_ns()) / 1'000'000;
      if (left_ms <= 0) return false;
      pollfd pf{out_, POLLIN, 0};
      if (::poll(&pf, 1, static_cast<int>(left_ms)) <= 0) continue;
      char buf[4096];
      const ssize_t n = ::read(out_, buf, sizeof buf);
      if (n <= 0) return text.find(needle) != std::string::npos;
      text.append(buf, static_cast<std::size_t>(n));
    }
    return true;
  }
  // Waits for the exit (reading the rest of the output); returns the exit code, −1 if signalled.
  int wait() {
    read_until("\x01never\x01", 60.0);
    int st = 0;
    ::waitpid(pid_, &st, 0);
    pid_ = -1;
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  }
  void signal(int s) { ::kill(pid_, s); }
  std::string text;

 private:
  pid_t pid_ = -1;
  int out_ = -1;
};

}  // namespace pedalwave::test
