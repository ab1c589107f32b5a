// FoxgloveServer: a live view of the telemetry without ROS — a WebSocket server speaking the
// Foxglove WebSocket protocol (subprotocol `foxglove.websocket.v1`, docs: github.com/foxglove/ws-protocol),
// which Foxglove ("Open connection" → Foxglove WebSocket, ws://127.0.0.1:PORT) connects to.
//
// On connection the server sends `serverInfo`, then `advertise` with one channel per topic
// (TelemetrySubscriber::topics(): id, topic = the ROS name, encoding `cdr`, schemaName = the ROS 2
// type, schema = its `ros2msg` text with dependencies, schemaEncoding `ros2msg`). A client sends
// `subscribe` {subscriptions: [{id, channelId}]} and `unsubscribe` {subscriptionIds}; for each
// subscription the server sends binary "message data" frames: opcode 0x01, uint32 subscription id,
// uint64 timestamp [ns, CLOCK_REALTIME at receipt], the CDR bytes as taken from DDS (encapsulation
// header included). A bad request gets a `status` message (level 2, error) saying why.
//
// WebSocket (RFC 6455: handshake, framing, ping/pong, close) is Debian's libwebsockets. The server
// runs its own thread (network I/O only); on_raw() — called where the subscriber is polled — copies
// a message only when some client is subscribed to its channel, and hands it over through a
// mutex-guarded queue. A slow client loses messages (once `max_queued_bytes` wait for it, new
// messages for it are dropped and counted), the monitor never waits for a client. Never on the
// real-time thread.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "pedalwave/telemetry/subscriber.hpp"

namespace pedalwave::telemetry {

struct FoxgloveServerOptions {
  std::string address = "127.0.0.1";       // IPv4 address to listen on ("0.0.0.0": all)
  int port = 8765;                          // TCP port (Foxglove's default 8765)
  std::string name = "pedalwave";           // serverInfo.name
  std::size_t max_queued_bytes = 8u << 20;  // [bytes] per client waiting to be sent
};

class FoxgloveServer final : public RawMessageListener {
 public:
  // Listens and starts the server thread. Throws std::runtime_error naming the address and port
  // when it cannot listen, std::invalid_argument for a topic whose type has no definition.
  FoxgloveServer(const std::vector<TopicInfo>& topics, FoxgloveServerOptions options);
  ~FoxgloveServer() override;  // closes every connection and joins the thread
  FoxgloveServer(const FoxgloveServer&) = delete;
  FoxgloveServer& operator=(const FoxgloveServer&) = delete;

  void on_raw(std::size_t topic, std::span<const std::byte> cdr, const MessageInfo&) override;

  int port() const;                          // the port listened on
  int clients() const;                       // connections open now
  std::uint64_t messages_sent() const;       // message data frames handed to the sockets
  std::uint64_t messages_dropped() const;    // dropped for a slow client

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace pedalwave::telemetry
