// Test support for the DDS tests: a per-process unique domain id (so parallel ctest runs, even
// from several build folders, never cross-talk), child processes running the test peer, and
// comparison helpers.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "dds_domain_lease.hpp"

extern char** environ;

namespace pedalwave::test {

// A child process (the test peer) with its stdout on a pipe.
class Child {
 public:
  // extra_env: "NAME=value" entries added to (and overriding) this process's environment.
  explicit Child(const std::vector<std::string>& argv,
                 const std::vector<std::string>& extra_env = {}) {
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0) throw std::runtime_error("pipe2 failed");
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_adddup2(&fa, fds[1], STDOUT_FILENO);
    std::vector<char*> args;
    for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    std::vector<std::string> env_store;
    for (char** e = environ; *e != nullptr; ++e) {
      const std::string kv(*e);
      const std::string name = kv.substr(0, kv.find('='));
      bool overridden = false;
      for (const auto& x : extra_env) overridden |= x.substr(0, x.find('=')) == name;
      if (!overridden) env_store.push_back(kv);
    }
    env_store.insert(env_store.end(), extra_env.begin(), extra_env.end());
    std::vector<char*> envp;
    for (auto& kv : env_store) envp.push_back(kv.data());
    envp.push_back(nullptr);
    const int rc = posix_spawn(&pid_, args[0], &fa, nullptr, args.data(), envp.data());
    posix_spawn_file_actions_destroy(&fa);
    ::close(fds[1]);
    if (rc != 0) {
      ::close(fds[0]);
      throw std::runtime_error("posix_spawn " + argv[0] + " failed");
    }
    out_ = ::fdopen(fds[0], "r");
  }
  ~Child() {
    if (pid_ > 0) {
      kill_hard();
    }
    if (out_ != nullptr) std::fclose(out_);
  }
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;

  // Next stdout line (without '\n'); "" at EOF.
  std::string read_line() {
    char buf[512];
    if (std::fgets(buf, sizeof buf, out_) == nullptr) return {};
    std::string s(buf);
    if (!s.empty() && s.back() == '\n') s.pop_back();
    return s;
  }
  // Reads lines until one starts with `prefix`; returns it ("" at EOF).
  std::string wait_for_line(const std::string& prefix) {
    for (;;) {
      std::string l = read_line();
      if (l.empty() && std::feof(out_)) return {};
      if (l.rfind(prefix, 0) == 0) return l;
    }
  }
  // Waits for exit; returns the exit status (or 128 + signal).
  int wait() {
    int st = 0;
    ::waitpid(pid_, &st, 0);
    pid_ = -1;
    return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
  }
  void kill_hard() {
    ::kill(pid_, SIGKILL);
    wait();
  }
  pid_t pid() const { return pid_; }

 private:
  pid_t pid_ = -1;
  std::FILE* out_ = nullptr;
};

inline std::string peer_path() { return PEDALWAVE_TELEMETRY_PEER; }

}  // namespace pedalwave::test
