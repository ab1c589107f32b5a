// The byte stream of a DYNAMIXEL Protocol 2.0 bus on a tty or pty: what the serial driver
// (pedalwave modules) and its X-series mode (stock servos + sensors) share — writing a buffer
// before a deadline, reading what is waiting and cutting it into packets, gathering answers until
// a deadline, and one request/answer exchange at configuration. The drivers keep what differs:
// which packet answers what (rolling counter / host-side timing), behind DxlPacketSink.
// write_all(), receive(), drop_partial(), gather() never allocate, lock, throw or block past their
// deadline.
#pragma once

#include <array>
#include <cstdint>

#include "pedalwave/drivers/dynamixel.hpp"
#include "pedalwave/interface/io.hpp"

namespace pedalwave::drivers {

// Where DxlLink hands each complete packet: status kOk or kChecksum (frames_rx and checksum are
// counted by the link; the sink flags the joint and classifies the answer), received at stamp_ns.
class DxlPacketSink {
 public:
  virtual void on_packet(dxl::DxlStatus s, const dxl::Packet& p, std::int64_t stamp_ns) noexcept = 0;

 protected:
  ~DxlPacketSink() = default;
};

class DxlLink {
 public:
  // fd: the tty (owned by the driver, not by the link).
  void attach(int fd) noexcept { fd_ = fd; }
  // Writes all n bytes, waiting (ppoll) for room in the output queue until until_ns
  // (CLOCK_MONOTONIC). false: an error, or the deadline passed.
  bool write_all(const std::uint8_t* p, std::size_t n, std::int64_t until_ns) noexcept;
  // Reads what is waiting (the link's silence measured at stamp_ns) and cuts it into packets for
  // sink. A run of bytes without a header counts once as malformed, as does any other framing
  // error; an overflowing buffer (cannot happen with sane packets) is dropped and resynchronized.
  void receive(std::int64_t stamp_ns, DriverCounters& c, DxlPacketSink& sink) noexcept;
  // At a cycle's start, after receive(): a packet still incomplete is a short read (malformed),
  // dropped.
  void drop_partial(DriverCounters& c) noexcept;
  // Waits until deadline_ns or until have ≥ want (the sink counts `have`): receive() stamped with
  // the reception time whenever the line has something; stops early when the far end is gone.
  void gather(std::int64_t deadline_ns, DriverCounters& c, DxlPacketSink& sink, const int& have,
              int want) noexcept;
  // Configuration (not the cycle): discards what waits on the line, sends one request and waits
  // up to timeout_ns for a status packet of `id` (with `params` parameter bytes or an error; −1:
  // any), then in packet().
  bool transact(const std::uint8_t* p, std::size_t n, std::uint8_t id, std::int64_t timeout_ns,
                int params = -1);
  const dxl::Packet& packet() const noexcept { return pkt_; }
  // After configuration: nothing of it is kept.
  void clear() noexcept { rx_len_ = 0; }

 private:
  int fd_ = -1;
  std::array<std::uint8_t, 4096> rx_{};
  std::size_t rx_len_ = 0;
  bool garbage_run_ = false;  // inside a run of bytes without a header
  SilenceMeter silence_;
  dxl::Packet pkt_{};
};

}  // namespace pedalwave::drivers
