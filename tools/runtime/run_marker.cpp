#include "run_marker.hpp"

#include <cerrno>
#include <cstring>
#include <ctime>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <system_error>

#include <fcntl.h>
#include <unistd.h>

namespace pedalwave::app {

namespace {

std::string errno_text(const std::string& what) { return what + ": " + std::strerror(errno); }

// Writes `text` to `path` durably: a temporary file beside it, fsync, rename over it, fsync of
// the folder. Returns an empty string or what failed.
std::string write_durably(const std::filesystem::path& dir, const std::filesystem::path& path,
                          const std::string& text) {
  const std::filesystem::path tmp = path.string() + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return errno_text("open " + tmp.string());
  std::string err;
  if (::write(fd, text.data(), text.size()) != static_cast<ssize_t>(text.size()))
    err = errno_text("write " + tmp.string());
  else if (::fsync(fd) != 0)
    err = errno_text("fsync " + tmp.string());
  ::close(fd);
  if (err.empty() && ::rename(tmp.c_str(), path.c_str()) != 0)
    err = errno_text("rename " + tmp.string() + " → " + path.string());
  if (err.empty()) {
    const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dfd >= 0) {
      (void)::fsync(dfd);
      ::close(dfd);
    }
  }
  return err;
}

}  // namespace

RunMarker::RunMarker(std::filesystem::path dir, std::string what)
    : dir_(std::move(dir)), path_(dir_ / "running"), what_(std::move(what)) {
  std::error_code ec;
  std::filesystem::create_directories(dir_, ec);
  if (ec) throw std::runtime_error("--state-dir " + dir_.string() + ": cannot create it: " + ec.message());
  if (::access(dir_.c_str(), W_OK | X_OK) != 0)
    throw std::runtime_error(errno_text("--state-dir " + dir_.string() + ": not writable"));
  found_ = std::filesystem::exists(path_, ec);
  if (found_) {
    std::ifstream f(path_);
    std::stringstream ss;
    ss << f.rdbuf();
    previous_ = ss.str();
    while (!previous_.empty() && (previous_.back() == '\n' || previous_.back() == ' '))
      previous_.pop_back();
    if (previous_.empty()) previous_ = "(empty marker)";
  }
}

void RunMarker::mark() {
  if (tried_) return;
  tried_ = true;
  char when[32] = "?";
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  if (::gmtime_r(&now, &tm)) std::strftime(when, sizeof when, "%Y-%m-%dT%H:%M:%SZ", &tm);
  const std::string text = "pid " + std::to_string(::getpid()) + ", config " + what_ +
                           ", walking since " + when + "\n";
  write_error_ = write_durably(dir_, path_, text);
  marked_ = write_error_.empty();
}

std::string RunMarker::clear() {
  std::error_code ec;
  std::filesystem::remove(path_.string() + ".tmp", ec);
  std::filesystem::remove(path_, ec);
  return ec ? "cannot remove " + path_.string() + ": " + ec.message() : std::string();
}

}  // namespace pedalwave::app
