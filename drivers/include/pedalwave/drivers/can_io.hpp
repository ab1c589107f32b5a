// One frame to or from a CAN socket (SocketCAN, or the socket pair the tests and the virtual robot
// use), received with the kernel's receive stamp: the I/O of the own-protocol driver, the CANopen
// master and the emulated modules and drives. Allocation-free; the caller owns the control buffer.
#pragma once

#include <linux/can.h>
#include <sys/socket.h>

#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <ctime>
#include <span>

namespace pedalwave::drivers {

struct ReceivedFrame {
  canfd_frame frame{};
  std::size_t bytes = 0;          // what recvmsg returned: CAN_MTU or CANFD_MTU for a whole frame
  bool truncated = false;         // MSG_TRUNC: larger than canfd_frame
  std::int64_t stamp_ns = 0;      // SCM_TIMESTAMPNS on CLOCK_MONOTONIC [ns]; 0 = not stamped
  // The stamp was taken by this recvmsg, not when the frame entered the kernel: a frame the
  // kernel did not stamp on entry is stamped by each socket's reader when it reads it (a loaded
  // vcan VM: 5–15 % of the SYNCs, the master's and the drives' stamps 0.01–0.8 ms apart). Such a
  // stamp says when this thread read the frame, not when it was on the bus.
  bool stamped_at_read = false;
  bool own = false;               // MSG_CONFIRM: a frame this socket sent, looped back (CAN_RAW_RECV_OWN_MSGS)
  bool have_rxq_ovfl = false;     // SO_RXQ_OVFL present (the socket's drop counter) …
  std::uint32_t rxq_ovfl = 0;     // … its value [-]
};

enum class Receive : std::uint8_t { kFrame, kNone, kClosed };

// One recvmsg(MSG_DONTWAIT) into `out` (EINTR retried). kNone: nothing queued (or an error, which
// surfaces as a missing frame); kClosed: the peer closed a socket pair. The realtime stamp is
// mapped to CLOCK_MONOTONIC by rt_minus_mono_ns (CLOCK_REALTIME − CLOCK_MONOTONIC); a zero stamp
// means "not stamped" (RX timestamping is switched on asynchronously); stamped_at_read says the
// kernel stamped it only now (a stamp not before the call).
inline Receive receive_frame(int fd, std::span<char> control, std::int64_t rt_minus_mono_ns,
                             ReceivedFrame& out) noexcept {
  for (;;) {
    out = ReceivedFrame{};
    timespec before{};  // on the stamps' own clock: no offset's error in the comparison
    ::clock_gettime(CLOCK_REALTIME, &before);
    iovec iov{&out.frame, sizeof out.frame};
    msghdr m{};
    m.msg_iov = &iov;
    m.msg_iovlen = 1;
    m.msg_control = control.data();
    m.msg_controllen = control.size();
    const ssize_t n = ::recvmsg(fd, &m, MSG_DONTWAIT);
    if (n < 0) {
      if (errno == EINTR) continue;
      return Receive::kNone;
    }
    if (n == 0) return Receive::kClosed;
    out.bytes = static_cast<std::size_t>(n);
    out.truncated = (m.msg_flags & MSG_TRUNC) != 0;
    out.own = (m.msg_flags & MSG_CONFIRM) != 0;
    for (cmsghdr* c = CMSG_FIRSTHDR(&m); c != nullptr; c = CMSG_NXTHDR(&m, c)) {
      if (c->cmsg_level != SOL_SOCKET) continue;
      if (c->cmsg_type == SCM_TIMESTAMPNS) {
        timespec ts{};
        std::memcpy(&ts, CMSG_DATA(c), sizeof ts);
        if (ts.tv_sec != 0 || ts.tv_nsec != 0) {
          out.stamp_ns = static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000LL + ts.tv_nsec - rt_minus_mono_ns;
          out.stamped_at_read = ts.tv_sec > before.tv_sec || (ts.tv_sec == before.tv_sec && ts.tv_nsec >= before.tv_nsec);
        }
      } else if (c->cmsg_type == SO_RXQ_OVFL) {
        std::memcpy(&out.rxq_ovfl, CMSG_DATA(c), sizeof out.rxq_ovfl);
        out.have_rxq_ovfl = true;
      }
    }
    return Receive::kFrame;
  }
}

enum class Send : std::uint8_t { kSent, kFull, kDown };

// One send(MSG_DONTWAIT) of a whole frame of `size` bytes (CAN_MTU or CANFD_MTU; EINTR retried).
// kFull: the socket's transmit queue is full (EAGAIN, ENOBUFS), the frame was not sent; kDown:
// any other error or a short write (ENETDOWN, ENXIO, EPIPE: the bus is gone). errno says why
// (EIO for a short write).
inline Send send_frame(int fd, const void* frame, std::size_t size) noexcept {
  for (;;) {
    const ssize_t r = ::send(fd, frame, size, MSG_DONTWAIT | MSG_NOSIGNAL);
    if (r == static_cast<ssize_t>(size)) return Send::kSent;
    if (r >= 0) {
      errno = EIO;
      return Send::kDown;
    }
    if (errno == EINTR) continue;
    return errno == EAGAIN || errno == EWOULDBLOCK || errno == ENOBUFS ? Send::kFull : Send::kDown;
  }
}

}  // namespace pedalwave::drivers
