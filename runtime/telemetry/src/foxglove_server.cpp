#include "pedalwave/telemetry/foxglove_server.hpp"

#include <arpa/inet.h>
#include <libwebsockets.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <cerrno>

#include <cstdio>
#include <cstring>
#include <deque>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <thread>

#include "pedalwave/telemetry/ros2_definitions.hpp"
#include "pedalwave/interface/clock.hpp"

namespace pedalwave::telemetry {

namespace {

using Json = nlohmann::json;

// One WebSocket message to send, with the LWS_PRE bytes of headroom lws_write() needs.
struct Frame {
  std::vector<unsigned char> buf;
  bool binary = false;
  std::size_t size() const { return buf.size() - LWS_PRE; }
};

Frame text_frame(const std::string& s) {
  Frame f;
  f.buf.resize(LWS_PRE + s.size());
  std::memcpy(f.buf.data() + LWS_PRE, s.data(), s.size());
  return f;
}

// Foxglove "message data": opcode 0x01, uint32 subscription id, uint64 timestamp [ns], payload.
Frame message_frame(std::uint32_t subscription, std::uint64_t t_ns, const std::vector<std::byte>& data) {
  Frame f;
  f.binary = true;
  f.buf.resize(LWS_PRE + 13 + data.size());
  unsigned char* p = f.buf.data() + LWS_PRE;
  p[0] = 0x01;
  for (int i = 0; i < 4; ++i) p[1 + i] = static_cast<unsigned char>(subscription >> (8 * i));
  for (int i = 0; i < 8; ++i) p[5 + i] = static_cast<unsigned char>(t_ns >> (8 * i));
  if (!data.empty()) std::memcpy(p + 13, data.data(), data.size());
  return f;
}

std::string status_json(int level, const std::string& message) {
  return Json{{"op", "status"}, {"level", level}, {"message", message}}.dump();
}

struct Client {
  std::map<std::uint32_t, std::size_t> subscriptions;  // subscription id → channel index
  std::deque<Frame> out;
  std::size_t out_bytes = 0;
  std::string rx;  // a text message being reassembled from fragments
};

// A message handed over by on_raw() to the server thread.
struct Pending {
  std::size_t channel = 0;
  std::uint64_t t_ns = 0;
  std::vector<std::byte> data;
};

int callback(lws* wsi, lws_callback_reasons reason, void* user, void* in, std::size_t len);

}  // namespace

struct FoxgloveServer::Impl {
  FoxgloveServerOptions opt;
  std::vector<TopicInfo> topics;
  std::string server_info, advertise;
  std::vector<std::atomic<int>> subscribers;  // per channel, over every client
  lws_protocols protocols[2]{};
  lws_context* ctx = nullptr;
  int port = 0;
  std::thread thread;
  std::atomic<bool> stop{false};
  std::mutex mu;                   // guards pending
  std::vector<Pending> pending;
  std::vector<Pending> spare;      // the server thread's swapped-out batch
  std::map<lws*, Client> clients;  // the server thread only
  std::atomic<int> n_clients{0};
  std::atomic<std::uint64_t> sent{0}, dropped{0};

  explicit Impl(std::size_t n) : subscribers(n) {}

  void enqueue(lws* wsi, Client& c, Frame f) {
    if (f.binary && c.out_bytes + f.size() > opt.max_queued_bytes) {
      ++dropped;
      return;
    }
    c.out_bytes += f.size();
    c.out.push_back(std::move(f));
    lws_callback_on_writable(wsi);
  }

  void handle_text(lws* wsi, Client& c, const std::string& text) {
    Json j;
    try {
      j = Json::parse(text);
    } catch (const std::exception& e) {
      enqueue(wsi, c, text_frame(status_json(2, std::string("not JSON: ") + e.what())));
      return;
    }
    const std::string op = j.is_object() && j.contains("op") && j["op"].is_string() ? j["op"].get<std::string>() : "";
    try {
      if (op == "subscribe") {
        for (const Json& s : j.at("subscriptions")) {
          const auto id = s.at("id").get<std::uint32_t>();
          const auto channel = s.at("channelId").get<std::uint64_t>();
          if (channel < 1 || channel > topics.size()) {
            enqueue(wsi, c, text_frame(status_json(2, "subscribe: no channel " + std::to_string(channel) +
                                                          " (channels are 1 … " + std::to_string(topics.size()) + ")")));
          } else if (c.subscriptions.count(id) != 0) {
            enqueue(wsi, c, text_frame(status_json(2, "subscribe: subscription id " + std::to_string(id) +
                                                          " is already in use")));
          } else {
            c.subscriptions[id] = channel - 1;
            ++subscribers[channel - 1];
          }
        }
      } else if (op == "unsubscribe") {
        for (const Json& s : j.at("subscriptionIds")) {
          const auto id = s.get<std::uint32_t>();
          if (const auto it = c.subscriptions.find(id); it != c.subscriptions.end()) {
            --subscribers[it->second];
            c.subscriptions.erase(it);
          } else {
            enqueue(wsi, c, text_frame(status_json(1, "unsubscribe: no subscription " + std::to_string(id))));
          }
        }
      } else {
        enqueue(wsi, c, text_frame(status_json(1, "op \"" + op + "\" is not supported by this server")));
      }
    } catch (const std::exception& e) {
      enqueue(wsi, c, text_frame(status_json(2, "bad " + op + " request: " + e.what())));
    }
  }

  // On the server thread: the messages on_raw() queued, to every subscription of their channel.
  void distribute() {
    {
      const std::lock_guard<std::mutex> lock(mu);
      spare.swap(pending);
    }
    for (const Pending& p : spare) {
      for (auto& [wsi, c] : clients) {
        for (const auto& [id, channel] : c.subscriptions) {
          if (channel == p.channel) enqueue(wsi, c, message_frame(id, p.t_ns, p.data));
        }
      }
    }
    spare.clear();
  }

  int on_callback(lws* wsi, lws_callback_reasons reason, void* in, std::size_t len) {
    switch (reason) {
      case LWS_CALLBACK_ESTABLISHED: {
        Client& c = clients[wsi];
        ++n_clients;
        enqueue(wsi, c, text_frame(server_info));
        enqueue(wsi, c, text_frame(advertise));
        return 0;
      }
      case LWS_CALLBACK_RECEIVE: {
        const auto it = clients.find(wsi);
        if (it == clients.end()) return 0;
        Client& c = it->second;
        if (lws_frame_is_binary(wsi)) {
          if (lws_is_first_fragment(wsi))
            enqueue(wsi, c, text_frame(status_json(1, "client binary messages (publishing, service "
                                                      "calls) are not supported by this server")));
          return 0;
        }
        c.rx.append(static_cast<const char*>(in), len);
        if (c.rx.size() > (1u << 20)) {
          c.rx.clear();
          enqueue(wsi, c, text_frame(status_json(2, "request larger than 1 MiB refused")));
          return 0;
        }
        if (lws_is_final_fragment(wsi) && lws_remaining_packet_payload(wsi) == 0) {
          const std::string text = std::move(c.rx);
          c.rx.clear();
          handle_text(wsi, c, text);
        }
        return 0;
      }
      case LWS_CALLBACK_SERVER_WRITEABLE: {
        const auto it = clients.find(wsi);
        if (it == clients.end() || it->second.out.empty()) return 0;
        Client& c = it->second;
        Frame& f = c.out.front();
        const int n = lws_write(wsi, f.buf.data() + LWS_PRE, f.size(),
                                f.binary ? LWS_WRITE_BINARY : LWS_WRITE_TEXT);
        if (n < static_cast<int>(f.size())) return -1;  // the connection failed: close it
        if (f.binary) ++sent;
        c.out_bytes -= f.size();
        c.out.pop_front();
        if (!c.out.empty()) lws_callback_on_writable(wsi);
        return 0;
      }
      case LWS_CALLBACK_CLOSED: {
        if (const auto it = clients.find(wsi); it != clients.end()) {
          for (const auto& [id, channel] : it->second.subscriptions) --subscribers[channel];
          clients.erase(it);
          --n_clients;
        }
        return 0;
      }
      case LWS_CALLBACK_EVENT_WAIT_CANCELLED:
        distribute();
        return 0;
      default:
        return lws_callback_http_dummy(wsi, reason, nullptr, in, len);
    }
  }
};

namespace {

int callback(lws* wsi, lws_callback_reasons reason, void* /*user*/, void* in, std::size_t len) {
  auto* impl = static_cast<FoxgloveServer::Impl*>(lws_context_user(lws_get_context(wsi)));
  if (impl == nullptr) return lws_callback_http_dummy(wsi, reason, nullptr, in, len);
  return impl->on_callback(wsi, reason, in, len);
}

// Why `address`:`port` cannot be listened on ("" = it can), found by binding a socket of our own
// the way libwebsockets will (SO_REUSEADDR): a clear reason (libwebsockets only says it failed),
// and its failure path is never taken in the common cases.
std::string listen_problem(const std::string& address, int port) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  if (::inet_pton(AF_INET, address.c_str(), &a.sin_addr) != 1) return "not an IPv4 address";
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return std::strerror(errno);
  const int one = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  std::string why;
  if (::bind(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a) != 0 || ::listen(fd, 1) != 0)
    why = std::strerror(errno);
  ::close(fd);
  return why;
}

void lws_log_line(int level, const char* line) {
  std::fprintf(stderr, "foxglove server (libwebsockets %s): %s", level == LLL_ERR ? "error" : "warning", line);
}

}  // namespace

FoxgloveServer::FoxgloveServer(const std::vector<TopicInfo>& topics, FoxgloveServerOptions options)
    : impl_(std::make_unique<Impl>(topics.size())) {
  Impl& m = *impl_;
  m.opt = std::move(options);
  m.topics = topics;
  if (m.opt.port < 0 || m.opt.port > 65535)
    throw std::invalid_argument("foxglove server: port " + std::to_string(m.opt.port) +
                                ": expected 0 … 65535");
  if (in_addr a{}; ::inet_pton(AF_INET, m.opt.address.c_str(), &a) != 1)
    throw std::invalid_argument("foxglove server: address \"" + m.opt.address +
                                "\": expected an IPv4 address (127.0.0.1, 0.0.0.0 for every interface)");
  if (const std::string why = listen_problem(m.opt.address, m.opt.port); !why.empty())
    throw std::runtime_error("foxglove server: cannot listen on " + m.opt.address + ":" +
                             std::to_string(m.opt.port) + ": " + why);
  Json channels = Json::array();
  for (std::size_t i = 0; i < topics.size(); ++i) {
    channels.push_back({{"id", i + 1},
                        {"topic", topics[i].topic},
                        {"encoding", "cdr"},
                        {"schemaName", topics[i].type},
                        {"schema", ros2msg_schema(topics[i].type)},
                        {"schemaEncoding", "ros2msg"}});
  }
  m.advertise = Json{{"op", "advertise"}, {"channels", channels}}.dump();
  m.server_info = Json{{"op", "serverInfo"},
                       {"name", m.opt.name},
                       {"capabilities", Json::array()},
                       {"supportedEncodings", Json::array()},
                       {"metadata", Json::object()},
                       {"sessionId", std::to_string(::getpid()) + "-" + std::to_string(::time(nullptr))}}
                      .dump();

  lws_set_log_level(LLL_ERR | LLL_WARN, lws_log_line);
  m.protocols[0].name = "foxglove.websocket.v1";
  m.protocols[0].callback = callback;
  m.protocols[0].rx_buffer_size = 64 * 1024;
  m.protocols[1] = {};  // the list's terminator
  lws_context_creation_info info{};
  info.port = m.opt.port;
  info.iface = m.opt.address.c_str();
  info.protocols = m.protocols;
  info.gid = static_cast<gid_t>(-1);
  info.uid = static_cast<uid_t>(-1);
  info.user = &m;
  info.options = LWS_SERVER_OPTION_DISABLE_IPV6;
  m.ctx = lws_create_context(&info);
  if (m.ctx == nullptr)
    throw std::runtime_error("foxglove server: cannot listen on " + m.opt.address + ":" +
                             std::to_string(m.opt.port) +
                             " (address not on this host, port in use, or no permission)");
  lws_vhost* vh = lws_get_vhost_by_name(m.ctx, "default");
  m.port = vh != nullptr ? lws_get_vhost_listen_port(vh) : m.opt.port;
  m.thread = std::thread([&m] {
    while (!m.stop.load()) {
      if (lws_service(m.ctx, 0) < 0) break;
    }
  });
}

FoxgloveServer::~FoxgloveServer() {
  Impl& m = *impl_;
  m.stop = true;
  lws_cancel_service(m.ctx);
  if (m.thread.joinable()) m.thread.join();
  lws_context_destroy(m.ctx);
}

void FoxgloveServer::on_raw(std::size_t topic, std::span<const std::byte> cdr, const MessageInfo&) {
  Impl& m = *impl_;
  if (topic >= m.subscribers.size() || m.subscribers[topic].load() <= 0) return;
  Pending p;
  p.channel = topic;
  p.t_ns = static_cast<std::uint64_t>(clock_ns(CLOCK_REALTIME));
  p.data.assign(cdr.begin(), cdr.end());
  {
    const std::lock_guard<std::mutex> lock(m.mu);
    m.pending.push_back(std::move(p));
  }
  lws_cancel_service(m.ctx);
}

int FoxgloveServer::port() const { return impl_->port; }
int FoxgloveServer::clients() const { return impl_->n_clients.load(); }
std::uint64_t FoxgloveServer::messages_sent() const { return impl_->sent.load(); }
std::uint64_t FoxgloveServer::messages_dropped() const { return impl_->dropped.load(); }

}  // namespace pedalwave::telemetry
