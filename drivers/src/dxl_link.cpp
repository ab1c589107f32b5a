#include "pedalwave/drivers/dxl_link.hpp"

#include <poll.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <span>

#include "pedalwave/drivers/posix_util.hpp"

namespace pedalwave::drivers {

bool DxlLink::write_all(const std::uint8_t* p, std::size_t n, std::int64_t until_ns) noexcept {
  std::size_t done = 0;
  while (done < n) {
    const ssize_t r = ::write(fd_, p + done, n - done);
    if (r > 0) {
      done += static_cast<std::size_t>(r);
      continue;
    }
    if (r < 0 && errno == EINTR) continue;
    if (r < 0 && errno != EAGAIN && errno != EWOULDBLOCK) return false;
    const std::int64_t remaining = until_ns - detail::monotonic_ns();
    if (remaining <= 0) return false;
    pollfd pf{fd_, POLLOUT, 0};
    const timespec ts = detail::to_timespec(remaining);
    if (::ppoll(&pf, 1, &ts, nullptr) <= 0) return false;
  }
  return true;
}

void DxlLink::receive(std::int64_t stamp_ns, DriverCounters& c, DxlPacketSink& sink) noexcept {
  bool got = false;
  for (;;) {
    if (rx_len_ == rx_.size()) {  // cannot happen with sane packets: drop and resynchronize
      ++c.malformed;
      rx_len_ = 0;
    }
    const ssize_t r = ::read(fd_, rx_.data() + rx_len_, rx_.size() - rx_len_);
    if (r > 0) {
      rx_len_ += static_cast<std::size_t>(r);
      got = true;
      continue;
    }
    if (r < 0 && errno == EINTR) continue;
    break;
  }
  if (got) silence_.on_rx(stamp_ns, c);
  std::size_t pos = 0;
  while (pos < rx_len_) {
    std::size_t used = 0;
    const dxl::DxlStatus s =
        dxl::parse_packet(std::span<const std::uint8_t>(rx_.data() + pos, rx_len_ - pos), pkt_, used);
    if (s == dxl::DxlStatus::kNeedMore) break;
    pos += used;
    if (s == dxl::DxlStatus::kGarbage) {
      if (!garbage_run_) ++c.malformed;  // one count per run of stray bytes
      garbage_run_ = true;
      continue;
    }
    garbage_run_ = false;
    ++c.frames_rx;
    if (s == dxl::DxlStatus::kChecksum) ++c.checksum;
    if (s == dxl::DxlStatus::kOk || s == dxl::DxlStatus::kChecksum) {
      sink.on_packet(s, pkt_, stamp_ns);
    } else {
      ++c.malformed;
    }
  }
  if (pos > 0) {
    std::memmove(rx_.data(), rx_.data() + pos, rx_len_ - pos);
    rx_len_ -= pos;
  }
}

void DxlLink::drop_partial(DriverCounters& c) noexcept {
  if (rx_len_ == 0) return;
  ++c.malformed;
  rx_len_ = 0;
  garbage_run_ = false;
}

void DxlLink::gather(std::int64_t deadline_ns, DriverCounters& c, DxlPacketSink& sink,
                     const int& have, int want) noexcept {
  while (have < want) {
    const std::int64_t remaining = deadline_ns - detail::monotonic_ns();
    if (remaining <= 0) break;
    pollfd pf{fd_, POLLIN, 0};
    const timespec ts = detail::to_timespec(remaining);
    const int r = ::ppoll(&pf, 1, &ts, nullptr);
    if (r < 0 && errno != EINTR) break;
    if (r > 0) {
      if (pf.revents & (POLLERR | POLLNVAL)) break;
      receive(detail::monotonic_ns(), c, sink);
      if ((pf.revents & POLLHUP) && !(pf.revents & POLLIN)) break;  // far end gone
    }
  }
}

bool DxlLink::transact(const std::uint8_t* p, std::size_t n, std::uint8_t id, std::int64_t timeout_ns,
                       int params) {
  // Whatever waits on the line is no answer to this request.
  std::uint8_t junk[256];
  while (::read(fd_, junk, sizeof junk) > 0) {
  }
  rx_len_ = 0;
  const std::int64_t until = detail::monotonic_ns() + timeout_ns;
  if (!write_all(p, n, until)) return false;
  for (;;) {
    std::size_t pos = 0;
    while (pos < rx_len_) {
      std::size_t used = 0;
      const dxl::DxlStatus s =
          dxl::parse_packet(std::span<const std::uint8_t>(rx_.data() + pos, rx_len_ - pos), pkt_, used);
      if (s == dxl::DxlStatus::kNeedMore) break;
      pos += used;
      // A status packet of `id` with the expected parameter count (or an error): a late answer
      // to an earlier try of another request has another length, and is skipped.
      if (s == dxl::DxlStatus::kOk && pkt_.instruction == dxl::kInstStatus && pkt_.id == id &&
          (params < 0 || pkt_.param_count == static_cast<std::size_t>(params) || (pkt_.error & 0x7F) != 0)) {
        rx_len_ = 0;
        return true;
      }
    }
    std::memmove(rx_.data(), rx_.data() + pos, rx_len_ - pos);
    rx_len_ -= pos;
    const std::int64_t left = until - detail::monotonic_ns();
    if (left <= 0) return false;
    pollfd pf{fd_, POLLIN, 0};
    const timespec ts = detail::to_timespec(left);
    if (::ppoll(&pf, 1, &ts, nullptr) > 0) {
      const ssize_t r = ::read(fd_, rx_.data() + rx_len_, rx_.size() - rx_len_);
      if (r > 0) rx_len_ += static_cast<std::size_t>(r);
    }
  }
}

}  // namespace pedalwave::drivers
