// The vcan tests' shared pieces: whether vcan is required (PEDALWAVE_REQUIRE_VCAN=1), a PATH
// lookup, the loud skip, can-utils' candump recording a CAN interface into a file, and one
// `candump -L` line decoded (written from candump's format, not with our codecs).
#pragma once

#include <linux/can.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace pedalwave::test {

inline bool vcan_required() {
  const char* v = std::getenv("PEDALWAVE_REQUIRE_VCAN");
  return v != nullptr && std::string(v) == "1";
}

inline std::string find_on_path(const std::string& name) {
  const char* path = std::getenv("PATH");
  std::stringstream dirs(path != nullptr ? path : "/usr/bin:/bin");
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    const std::string c = (dir.empty() ? "." : dir) + "/" + name;
    if (::access(c.c_str(), X_OK) == 0) return c;
  }
  return {};
}

#define VCAN_SKIP_OR_FAIL(msg)                                                       \
  do {                                                                                 \
    if (vcan_required()) GTEST_FAIL() << "PEDALWAVE_REQUIRE_VCAN=1: " << msg;          \
    std::fprintf(stderr, "\n*** SKIPPED: %s\n*** Run it inside the test VM: "          \
                 "tools/scripts/vm/test-vcan.sh <build dir>\n\n", std::string(msg).c_str()); \
    GTEST_SKIP() << msg;                                                               \
  } while (0)

// `candump -L -d -r 4194304 vcan0` writing into a file (no pipe back-pressure on candump while
// the loop runs: 3000 frames/s).
class Candump {
 public:
  Candump(const std::string& exe, const std::string& file, const char* iface = "vcan0") : file_(file) {
    const int out = ::open(file.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (out < 0) return;
    std::string a0 = exe, a1 = "-L", a2 = "-d", a3 = "-r", a4 = "4194304", a5 = iface;
    char* argv[] = {a0.data(), a1.data(), a2.data(), a3.data(), a4.data(), a5.data(), nullptr};
    const pid_t parent = ::getpid();
    pid_ = ::fork();
    if (pid_ == 0) {
      if (::prctl(PR_SET_PDEATHSIG, SIGKILL) != 0 || ::getppid() != parent) ::_exit(126);
      if (::dup2(out, STDOUT_FILENO) < 0) ::_exit(126);
      ::execv(exe.c_str(), argv);
      ::_exit(127);
    }
    ::close(out);
  }
  ~Candump() { stop(); }
  bool running() const { return pid_ > 0; }
  int stop() {
    if (pid_ <= 0) return -1;
    ::kill(pid_, SIGTERM);
    int status = 0;
    ::waitpid(pid_, &status, 0);
    pid_ = -1;
    return status;
  }
  // The lines candump has written so far.
  std::vector<std::string> lines() const {
    std::ifstream in(file_);
    std::vector<std::string> v;
    for (std::string l; std::getline(in, l);) v.push_back(l);
    return v;
  }

 private:
  std::string file_;
  pid_t pid_ = -1;
};

// One `candump -L` line: "(1700000000.123456) vcan0 181#0011223344556677".
struct Frame {
  double stamp_s = 0;
  std::string iface;
  canid_t id = 0;
  bool fd = false;
  std::vector<std::uint8_t> data;
};

inline std::optional<Frame> parse(const std::string& l) {
  Frame f;
  const auto close = l.find(") ");
  if (l.empty() || l[0] != '(' || close == std::string::npos) return std::nullopt;
  f.stamp_s = std::strtod(l.c_str() + 1, nullptr);
  const auto sp = l.find(' ', close + 2);
  if (sp == std::string::npos) return std::nullopt;
  f.iface = l.substr(close + 2, sp - close - 2);
  std::string fr = l.substr(sp + 1);
  while (!fr.empty() && (fr.back() == '\r' || fr.back() == ' ')) fr.pop_back();
  const auto hash = fr.find('#');
  if (hash == std::string::npos || hash == 0) return std::nullopt;
  f.id = static_cast<canid_t>(std::stoul(fr.substr(0, hash), nullptr, 16));
  if (hash == 8) f.id |= CAN_EFF_FLAG;
  std::string rest = fr.substr(hash + 1);
  if (!rest.empty() && rest[0] == '#') {
    f.fd = true;
    rest = rest.size() >= 2 ? rest.substr(2) : "";
  }
  if (rest.size() % 2 != 0) return std::nullopt;
  for (std::size_t i = 0; i < rest.size(); i += 2)
    f.data.push_back(static_cast<std::uint8_t>(std::stoul(rest.substr(i, 2), nullptr, 16)));
  return f;
}


}  // namespace pedalwave::test
