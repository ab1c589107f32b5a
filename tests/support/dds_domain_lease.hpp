// A DDS domain id of this process's own: parallel ctest runs (even from several build folders)
// never share a domain, so DDS tests never cross-talk.
#pragma once

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cstdint>
#include <stdexcept>
#include <string>

namespace pedalwave::test {

// Holds an exclusive flock on /tmp/pedalwave-dds-domain-<id>.lock for the life of the process
// (released by the kernel if the process dies): no two live holders share a domain id.
class DomainLease {
 public:
  DomainLease() {
    for (std::uint32_t id = 100; id <= 230; ++id) {
      const std::string path = "/tmp/pedalwave-dds-domain-" + std::to_string(id) + ".lock";
      const int fd = ::open(path.c_str(), O_CREAT | O_RDWR | O_CLOEXEC, 0666);
      if (fd < 0) continue;
      if (::flock(fd, LOCK_EX | LOCK_NB) == 0) {
        fd_ = fd;
        id_ = id;
        return;
      }
      ::close(fd);
    }
    throw std::runtime_error("no free DDS test domain id in 100..230");
  }
  ~DomainLease() {
    if (fd_ >= 0) ::close(fd_);
  }
  DomainLease(const DomainLease&) = delete;
  DomainLease& operator=(const DomainLease&) = delete;
  std::uint32_t id() const { return id_; }

 private:
  int fd_ = -1;
  std::uint32_t id_ = 0;
};

// One lease per test process (the DDS domain instance is per process anyway).
inline std::uint32_t dds_domain_id() {
  static DomainLease lease;
  return lease.id();
}

}  // namespace pedalwave::test
