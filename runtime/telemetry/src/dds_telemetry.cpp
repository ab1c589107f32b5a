#include "pedalwave/telemetry/dds_telemetry.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <optional>
#include <cmath>
#include <ctime>
#include <mutex>
#include <thread>
#include <vector>

#include "convert.hpp"
#include "domain.hpp"
#include "pedalwave/telemetry/command_validation.hpp"
#include "pedalwave/telemetry/names.hpp"
#include "pedalwave/telemetry/ros_standard.hpp"
#include "pedalwave/interface/clock.hpp"

namespace pedalwave::telemetry {

using namespace detail;

namespace {

using pedalwave::clock_ns;
using pedalwave::monotonic_ns;

// The runtime's outcome text of each command kind starts with this (runtime.cpp,
// apply_operator_command); the event carries the command id as its value.
const char* outcome_prefix(runtime::OperatorCommandKind k) noexcept {
  switch (k) {
    case runtime::OperatorCommandKind::kStartWalking: return "start walking";
    case runtime::OperatorCommandKind::kStopWalking: return "stop walking";
    case runtime::OperatorCommandKind::kSetGait: return "set gait";
    case runtime::OperatorCommandKind::kEmergencyStop: return "operator emergency stop";
  }
  return "";
}

bool starts_with(const char* s, const char* prefix) noexcept {
  return std::strncmp(s, prefix, std::strlen(prefix)) == 0;
}

struct Counter {
  std::atomic<std::uint64_t> n{0};
  void add() noexcept { n.fetch_add(1, std::memory_order_relaxed); }
  std::uint64_t get() const noexcept { return n.load(std::memory_order_relaxed); }
};

}  // namespace

struct DdsTelemetry::Impl {
  TelemetryConfig cfg;
  CommandHandler handler;
  std::shared_ptr<Domain> domain;
  Entity participant;
  dds_entity_t w_joint = 0, w_ctrl = 0, w_obs = 0, w_timing = 0;
  dds_entity_t w_mode = 0, w_fault = 0, w_desc = 0, w_ack = 0;
  dds_entity_t w_js = 0, w_diag = 0, w_urdf = 0, w_tf = 0;
  dds_entity_t r_cmd = 0, r_estop = 0;
  dds_entity_t waitset = 0, cmd_cond = 0, estop_cond = 0, stop_guard = 0;
  std::thread cmd_thread;
  std::string ns, robot, prefix;        // ROS namespace, robot name, frame prefix
  TopicNames topics{""};

  Counter joint, ctrl, obs, timing, mode_events, fault_events, descs, errors, accepted, rejected,
      executed, ignored, standard;

  // Commands queued for the runtime, waiting for their outcome event (command thread adds,
  // telemetry thread resolves, command thread times out).
  struct Pending {
    runtime::OperatorCommand cmd;
    std::int64_t deadline_ns = 0;      // CLOCK_MONOTONIC [ns]
  };
  std::mutex pending_mutex;
  std::vector<Pending> pending;

  // ---- telemetry-thread state (on_description / on_cycle / on_event) ----
  HeaderContext header;                // frame = robot name, offset to the stamp clock
  std::uint64_t mode_seq = 0, fault_seq = 0;   // event_seq counters
  int links = 0;                       // N from the description (0: none yet)
  double link_length = 0.0;            // 2l [m]
  // joint_states
  std::vector<std::string> joint_names;
  std::vector<char*> joint_name_ptrs;
  std::array<double, runtime::kMaxJoints> alpha_dot{};
  std::array<double, runtime::kMaxJoints> prev_alpha{};
  std::int64_t prev_t_ns = 0;
  bool have_prev = false;
  // tf
  std::vector<std::string> frame_names;          // odom, link_1 … link_N (prefixed)
  std::vector<geometry_msgs_msg_dds__TransformStamped_> tf_buf;
  std::vector<PlanarPose> poses;
  // diagnostics
  std::int64_t next_diag_ns = 0;
  std::uint8_t last_mode = 0;
  std::uint32_t last_overruns = 0, overruns_at_last_diag = 0;
  std::uint64_t last_ring_drops = 0;
  std::int32_t last_wake_latency_ns = 0;
  std::uint64_t faults_seen = 0;
  std::optional<runtime::EventSample> last_fault;
  std::string urdf;

  // Messages reused every call (their sequences are re-pointed at the sample each time).
  pedalwave_msg_dds__JointState_ m_joint{};
  pedalwave_msg_dds__ControllerState_ m_ctrl{};
  pedalwave_msg_dds__ObserverState_ m_obs{};
  pedalwave_msg_dds__LoopTiming_ m_timing{};

  dds_entity_t make_topic(const dds_topic_descriptor_t* desc, const char* name) {
    return check(dds_create_topic(participant.get(), desc, name, nullptr, nullptr),
                 "dds_create_topic");
  }
  dds_entity_t make_writer(const dds_topic_descriptor_t* desc, const char* name, QosClass qc) {
    const dds_entity_t topic = make_topic(desc, name);
    dds_qos_t* q = make_qos(qc);
    const dds_entity_t w = dds_create_writer(participant.get(), topic, q, nullptr);
    dds_delete_qos(q);
    return check(w, "dds_create_writer");
  }

  void write(dds_entity_t w, const void* msg, Counter& ok, const char* topic) {
    const dds_return_t rc = dds_write(w, msg);
    if (rc == DDS_RETCODE_OK) {
      ok.add();
      return;
    }
    errors.add();
    // Rate-limited: the first few, then every 1000th.
    const std::uint64_t n = errors.get();
    if (n <= 5 || n % 1000 == 0) {
      spdlog::warn("telemetry: write on {} failed: {} ({} write errors so far)", topic,
                   dds_strretcode(rc), n);
    }
  }

  void publish_ack(const runtime::OperatorCommand& c, AckStatus status, const char* reason) {
    pedalwave_msg_dds__CommandAck_ ack{};
    const std::int64_t now = monotonic_ns();
    fill_header(header_now(), now, ack.header);
    copy_bounded(ack.robot, robot.c_str());
    ack.id = c.id;
    ack.kind = static_cast<std::uint8_t>(c.kind);
    ack.status = static_cast<std::uint8_t>(status);
    ack.stamp_ns = now;
    copy_bounded(ack.reason, reason);
    // Counted before the write: whoever holds the ack sees the count.
    if (status == AckStatus::kExecuted) executed.add();
    if (status == AckStatus::kRejected) rejected.add();
    Counter dummy;
    write(w_ack, &ack, dummy, topics.command_ack.c_str());
  }

  // The header context for a stamp taken now, on any thread (the offset is recomputed).
  HeaderContext header_now() const {
    HeaderContext h;
    h.frame_id = robot.c_str();
    h.offset_ns = cfg.stamp_clock == StampClock::kRealtime
                      ? clock_ns(CLOCK_REALTIME) - clock_ns(CLOCK_MONOTONIC)
                      : 0;
    return h;
  }

  // `estop_topic`: it came on rt/pedalwave/emergency_stop, where only an e-stop is honoured
  // (DDS Security may grant that topic to identities that may not command anything else).
  void handle_command(const pedalwave_msg_dds__OperatorCommand_& m, bool estop_topic) {
    const std::string target(m.target, strnlen(m.target, sizeof(m.target)));
    if (target != robot && target != "*") {
      ignored.add();
      spdlog::debug("telemetry: command id {} for \"{}\" ignored (this robot is \"{}\")", m.id,
                    target, robot);
      return;
    }
    const runtime::OperatorCommand c = to_command(m);
    CommandDecision d = validate_command(c, cfg);
    if (estop_topic && d.accepted && c.kind != runtime::OperatorCommandKind::kEmergencyStop) {
      d = {false, "only emergency_stop is honoured on /pedalwave/emergency_stop"};
    }
    if (d.accepted && !handler) {
      d = {false, "no command handler installed (telemetry-only process)"};
    } else if (d.accepted) {
      // Registered before the handler hands it over, and QUEUED acked under the same lock: the
      // outcome (resolve_outcomes, telemetry thread, same lock) can neither miss the command nor
      // overtake its QUEUED ack.
      std::lock_guard lock(pending_mutex);
      pending.push_back(
          {c, monotonic_ns() + static_cast<std::int64_t>(cfg.command_outcome_timeout_s * 1e9)});
      if (handler(c)) {
        accepted.add();
        spdlog::info("telemetry: command {} id {} from \"{}\" queued", command_kind_name(m.kind),
                     m.id, m.sender);
        publish_ack(c, AckStatus::kQueued, "queued for the real-time loop");
        return;
      }
      pending.pop_back();
      d = {false, "runtime command mailbox full; retry"};
    }
    spdlog::warn("telemetry: command {} id {} from \"{}\" rejected: {}",
                 command_kind_name(m.kind), m.id, m.sender, d.reason);
    publish_ack(c, AckStatus::kRejected, d.reason.c_str());
  }

  // Telemetry thread: a runtime event may be the outcome of queued commands.
  void resolve_outcomes(const runtime::EventSample& e) {
    if (e.fault != runtime::FaultClass::kNone) return;
    const char* text = e.text.data();
    std::vector<Pending> done;
    {
      std::lock_guard lock(pending_mutex);
      if (pending.empty()) return;
      for (auto it = pending.begin(); it != pending.end();) {
        const runtime::OperatorCommand& c = it->cmd;
        const bool estop = c.kind == runtime::OperatorCommandKind::kEmergencyStop;
        const bool match =
            estop ? (e.to == runtime::Mode::kSafeStop && starts_with(text, outcome_prefix(c.kind)))
                  : (e.value == static_cast<double>(c.id) &&
                     starts_with(text, outcome_prefix(c.kind)));
        if (match) {
          done.push_back(*it);
          it = pending.erase(it);
        } else {
          ++it;
        }
      }
    }
    for (const Pending& p : done) {
      const bool ok = e.severity == runtime::Severity::kInfo;
      char reason[sizeof(e.text) + 1];
      std::copy(e.text.begin(), e.text.end(), reason);
      reason[sizeof(e.text)] = '\0';
      spdlog::info("telemetry: command {} id {} {}: {}",
                   command_kind_name(static_cast<std::uint8_t>(p.cmd.kind)), p.cmd.id,
                   ok ? "executed" : "refused by the runtime", reason);
      publish_ack(p.cmd, ok ? AckStatus::kExecuted : AckStatus::kRejected, reason);
    }
  }

  // Command thread: final REJECTED acks for commands without an outcome in time. Returns the
  // time to the next deadline (DDS_INFINITY if none).
  dds_duration_t expire_outcomes() {
    const std::int64_t now = monotonic_ns();
    std::vector<Pending> expired;
    dds_duration_t next = DDS_INFINITY;
    {
      std::lock_guard lock(pending_mutex);
      for (auto it = pending.begin(); it != pending.end();) {
        if (it->deadline_ns <= now) {
          expired.push_back(*it);
          it = pending.erase(it);
        } else {
          next = std::min<dds_duration_t>(next, it->deadline_ns - now);
          ++it;
        }
      }
    }
    for (const Pending& p : expired) {
      const std::string why = fmt::format("no outcome from the real-time loop within {:g} s",
                                          cfg.command_outcome_timeout_s);
      spdlog::warn("telemetry: command id {}: {}", p.cmd.id, why);
      publish_ack(p.cmd, AckStatus::kRejected, why.c_str());
    }
    return next;
  }

  // ---- standard ROS 2 topics (telemetry thread) ----

  void set_description(const runtime::RobotDescription& d) {
    links = std::clamp(d.links, 0, runtime::kMaxJoints + 1);
    link_length = d.link_length;
    joint_names.clear();
    joint_name_ptrs.clear();
    for (int j = 1; j < links; ++j) joint_names.push_back(prefix + joint_name(j));
    for (auto& n : joint_names) joint_name_ptrs.push_back(n.data());
    frame_names.clear();
    frame_names.push_back(prefix + "odom");
    for (int i = 1; i <= links; ++i) frame_names.push_back(prefix + link_name(i));
    tf_buf.assign(static_cast<std::size_t>(links), geometry_msgs_msg_dds__TransformStamped_{});
    poses.assign(static_cast<std::size_t>(links), PlanarPose{});
    have_prev = false;
    try {
      urdf = make_urdf(d, prefix);
    } catch (const std::exception& ex) {
      spdlog::warn("telemetry: no URDF published: {}", ex.what());
      urdf.clear();
    }
    if (!urdf.empty()) {
      std_msgs_msg_dds__String_ msg{};
      msg.data = urdf.data();
      write(w_urdf, &msg, standard, topics.robot_description_urdf.c_str());
    }
  }

  void publish_joint_states_and_tf(const runtime::CycleSample& s) {
    if (joint_name_ptrs.empty()) return;   // no description yet: no joint names to publish
    const int n = std::min(clamp_joints(s.joints), static_cast<int>(joint_name_ptrs.size()));
    // α̇ by backward difference between consecutive samples the sink received (every cycle
    // reaches the sink, decimation applies to publishing only); β̇ before the first one.
    const double dt = have_prev ? static_cast<double>(s.t_ns - prev_t_ns) * 1e-9 : 0.0;
    for (int j = 0; j < n; ++j) {
      const auto js = static_cast<std::size_t>(j);
      alpha_dot[js] = dt > 0.0 ? (s.alpha[js] - prev_alpha[js]) / dt : s.beta_dot[js];
    }
    sensor_msgs_msg_dds__JointState_ js{};
    fill_header(header, s.t_ns, js.header);
    js.name._length = js.name._maximum = static_cast<std::uint32_t>(n);
    js.name._buffer = joint_name_ptrs.data();
    js.name._release = false;
    js.position = view(s.alpha, n);
    js.velocity = view(alpha_dot, n);
    js.effort = view(s.tau_sea, n);
    write(w_js, &js, standard, topics.joint_states.c_str());

    if (links < 2 || n != links - 1) return;
    chain_poses(s.alpha.data(), links, link_length, s.body[0], s.body[1], s.body[2],
                poses.data());
    const auto stamp = ros_time(s.t_ns + header.offset_ns);
    for (int i = 0; i < links; ++i) {
      auto& t = tf_buf[static_cast<std::size_t>(i)];
      const PlanarPose& p = poses[static_cast<std::size_t>(i)];
      t.header.stamp = stamp;
      t.header.frame_id = frame_names[static_cast<std::size_t>(i)].data();
      t.child_frame_id = frame_names[static_cast<std::size_t>(i) + 1].data();
      t.transform.translation = {p.x, 0.0, p.z};
      const auto q = planar_quaternion(p.theta);
      t.transform.rotation = {q[0], q[1], q[2], q[3]};
    }
    tf2_msgs_msg_dds__TFMessage_ tf{};
    tf.transforms._length = tf.transforms._maximum = static_cast<std::uint32_t>(links);
    tf.transforms._buffer = tf_buf.data();
    tf.transforms._release = false;
    write(w_tf, &tf, standard, topics.tf.c_str());
  }

  // /diagnostics: three statuses (mode, loop, faults) of this robot.
  void publish_diagnostics(std::int64_t t_ns) {
    struct Status {
      std::uint8_t level;
      std::string name, message;
      std::vector<std::pair<std::string, std::string>> values;
    };
    std::vector<Status> st;
    st.push_back({mode_level(last_mode), robot + ": mode",
                  std::string("mode ") + mode_c_str(last_mode),
                  {{"mode", mode_c_str(last_mode)}}});
    const bool overran = last_overruns != overruns_at_last_diag;
    overruns_at_last_diag = last_overruns;
    st.push_back({static_cast<std::uint8_t>(overran ? 1 : 0), robot + ": real-time loop",
                  overran ? "deadline overruns since the last report" : "on time",
                  {{"overruns", std::to_string(last_overruns)},
                   {"ring_drops", std::to_string(last_ring_drops)},
                   {"wake_latency_ns", std::to_string(last_wake_latency_ns)}}});
    if (last_fault) {
      const auto& f = *last_fault;
      char text[sizeof(f.text) + 1];
      std::copy(f.text.begin(), f.text.end(), text);
      text[sizeof(f.text)] = '\0';
      st.push_back({severity_level(static_cast<std::uint8_t>(f.severity)), robot + ": faults",
                    text,
                    {{"class", fault_class_c_str(static_cast<std::uint8_t>(f.fault))},
                     {"severity", severity_c_str(static_cast<std::uint8_t>(f.severity))},
                     {"joint", f.joint >= 0 ? std::to_string(f.joint + 1) : "none"},
                     {"value", std::to_string(f.value)},
                     {"threshold", std::to_string(f.threshold)},
                     {"faults_so_far", std::to_string(faults_seen)}}});
    } else {
      st.push_back({0, robot + ": faults", "no fault", {{"faults_so_far", "0"}}});
    }
    // C view of st (pointers into it; dds_write serializes synchronously).
    std::vector<std::vector<diagnostic_msgs_msg_dds__KeyValue_>> kvs(st.size());
    std::vector<diagnostic_msgs_msg_dds__DiagnosticStatus_> cs(st.size());
    for (std::size_t i = 0; i < st.size(); ++i) {
      for (auto& [k, v] : st[i].values) kvs[i].push_back({k.data(), v.data()});
      cs[i].level = st[i].level;
      cs[i].name = st[i].name.data();
      cs[i].message = st[i].message.data();
      cs[i].hardware_id = robot.data();
      cs[i].values._length = cs[i].values._maximum = static_cast<std::uint32_t>(kvs[i].size());
      cs[i].values._buffer = kvs[i].data();
      cs[i].values._release = false;
    }
    diagnostic_msgs_msg_dds__DiagnosticArray_ msg{};
    fill_header(header, t_ns, msg.header);
    msg.status._length = msg.status._maximum = static_cast<std::uint32_t>(cs.size());
    msg.status._buffer = cs.data();
    msg.status._release = false;
    write(w_diag, &msg, standard, topics.diagnostics.c_str());
    next_diag_ns = t_ns + static_cast<std::int64_t>(cfg.diagnostics_period_s * 1e9);
  }

  void command_loop() {
    constexpr std::uint32_t kBatch = 16;
    std::array<dds_attach_t, 3> triggered{};
    for (;;) {
      const dds_duration_t timeout = expire_outcomes();
      const dds_return_t n =
          dds_waitset_wait(waitset, triggered.data(), triggered.size(), timeout);
      bool stop = false;
      dds_read_guardcondition(stop_guard, &stop);
      if (stop) return;
      if (n < 0) {
        spdlog::error("telemetry: command waitset failed: {}", dds_strretcode(n));
        return;
      }
      // Take everything that arrived on both command topics (loaned samples, returned after
      // handling). E-stops first.
      for (const dds_entity_t cond : {estop_cond, cmd_cond}) {
        for (;;) {
          std::array<void*, kBatch> buf{};
          std::array<dds_sample_info_t, kBatch> info{};
          const dds_return_t got = dds_take(cond, buf.data(), info.data(), kBatch, kBatch);
          if (got <= 0) break;
          for (dds_return_t i = 0; i < got; ++i) {
            if (info[static_cast<std::size_t>(i)].valid_data) {
              handle_command(*static_cast<const pedalwave_msg_dds__OperatorCommand_*>(
                                 buf[static_cast<std::size_t>(i)]),
                             cond == estop_cond);
            }
          }
          dds_return_loan(cond, buf.data(), got);
        }
      }
    }
  }
};

DdsTelemetry::DdsTelemetry(const TelemetryConfig& config, CommandHandler on_command)
    : impl_(std::make_unique<Impl>()) {
  config.validate();
  Impl& m = *impl_;
  m.cfg = config;
  m.handler = std::move(on_command);
  m.ns = config.effective_namespace();
  m.robot = config.robot_name;
  m.prefix = frame_prefix(m.ns);
  m.topics = TopicNames(m.ns);
  m.header = m.header_now();
  m.domain = acquire_domain(config.domain());
  m.participant = Entity(m.domain->create_participant());
  const TopicNames& t = m.topics;

  m.w_joint = m.make_writer(&pedalwave_msg_dds__JointState__desc, t.joint_state.c_str(),
                            QosClass::kState);
  m.w_ctrl = m.make_writer(&pedalwave_msg_dds__ControllerState__desc, t.controller_state.c_str(),
                           QosClass::kState);
  m.w_obs = m.make_writer(&pedalwave_msg_dds__ObserverState__desc, t.observer_state.c_str(),
                          QosClass::kState);
  m.w_timing = m.make_writer(&pedalwave_msg_dds__LoopTiming__desc, t.loop_timing.c_str(),
                             QosClass::kState);
  m.w_mode = m.make_writer(&pedalwave_msg_dds__ModeEvent__desc, t.mode_event.c_str(),
                           QosClass::kEvent);
  m.w_fault = m.make_writer(&pedalwave_msg_dds__FaultEvent__desc, t.fault_event.c_str(),
                            QosClass::kEvent);
  m.w_desc = m.make_writer(&pedalwave_msg_dds__RobotDescription__desc, t.description.c_str(),
                           QosClass::kDescription);
  m.w_ack = m.make_writer(&pedalwave_msg_dds__CommandAck__desc, t.command_ack.c_str(),
                          QosClass::kCommand);
  if (config.standard_topics) {
    m.w_js = m.make_writer(&sensor_msgs_msg_dds__JointState__desc, t.joint_states.c_str(),
                           QosClass::kRos);
    m.w_tf = m.make_writer(&tf2_msgs_msg_dds__TFMessage__desc, t.tf.c_str(), QosClass::kRos);
    m.w_diag = m.make_writer(&diagnostic_msgs_msg_dds__DiagnosticArray__desc,
                             t.diagnostics.c_str(), QosClass::kRos);
    m.w_urdf = m.make_writer(&std_msgs_msg_dds__String__desc, t.robot_description_urdf.c_str(),
                             QosClass::kDescription);
  }

  // Command reader + waitset (read condition on any new sample, guard condition to stop).
  const dds_entity_t cmd_topic =
      m.make_topic(&pedalwave_msg_dds__OperatorCommand__desc, t.command.c_str());
  dds_qos_t* q = make_qos(QosClass::kCommand);
  m.r_cmd = check(dds_create_reader(m.participant.get(), cmd_topic, q, nullptr),
                  "dds_create_reader(command)");
  const dds_entity_t estop_topic =
      m.make_topic(&pedalwave_msg_dds__OperatorCommand__desc, t.emergency_stop.c_str());
  m.r_estop = check(dds_create_reader(m.participant.get(), estop_topic, q, nullptr),
                    "dds_create_reader(emergency_stop)");
  dds_delete_qos(q);
  m.cmd_cond = check(dds_create_readcondition(m.r_cmd, DDS_ANY_STATE), "dds_create_readcondition");
  m.estop_cond =
      check(dds_create_readcondition(m.r_estop, DDS_ANY_STATE), "dds_create_readcondition");
  m.stop_guard =
      check(dds_create_guardcondition(m.participant.get()), "dds_create_guardcondition");
  m.waitset = check(dds_create_waitset(m.participant.get()), "dds_create_waitset");
  check(dds_waitset_attach(m.waitset, m.cmd_cond, 0), "dds_waitset_attach");
  check(dds_waitset_attach(m.waitset, m.stop_guard, 1), "dds_waitset_attach");
  check(dds_waitset_attach(m.waitset, m.estop_cond, 2), "dds_waitset_attach");
  m.cmd_thread = std::thread([this] { impl_->command_loop(); });

  spdlog::info("telemetry: robot \"{}\" namespace \"{}\", DDS domain {} on {}, commands {}, {}",
               m.robot, m.ns.empty() ? "/" : m.ns, config.domain_id,
               config.interface.empty() ? std::string("Cyclone's choice of interface")
                                        : "\"" + config.interface + "\"",
               config.enable_commands ? "enabled" : "disabled (e-stop only)",
               describe_security(config.security));
}

DdsTelemetry::~DdsTelemetry() {
  if (impl_->cmd_thread.joinable()) {
    dds_set_guardcondition(impl_->stop_guard, true);
    impl_->cmd_thread.join();
  }
  // Commands still waiting for their outcome get their final ack now: no answer will come.
  std::vector<Impl::Pending> left;
  {
    std::lock_guard lock(impl_->pending_mutex);
    left.swap(impl_->pending);
  }
  for (const auto& p : left) {
    impl_->publish_ack(p.cmd, AckStatus::kRejected,
                       "the robot's telemetry stopped before the real-time loop's outcome");
  }
  impl_->participant.reset();  // deletes topics, writers, reader, conditions, waitset
}

void DdsTelemetry::on_description(const runtime::RobotDescription& d) {
  Impl& m = *impl_;
  m.header = m.header_now();
  pedalwave_msg_dds__RobotDescription_ msg{};
  fill(d, m.cfg.decimation, m.ns.c_str(), msg);
  m.write(m.w_desc, &msg, m.descs, m.topics.description.c_str());
  if (m.cfg.standard_topics) m.set_description(d);
}

void DdsTelemetry::on_cycle(const runtime::CycleSample& s) {
  Impl& m = *impl_;
  const Decimation& dec = m.cfg.decimation;
  const auto due = [&s](int k) { return s.seq % static_cast<std::uint64_t>(k) == 0; };
  // The stamp clock's offset, sampled once per cycle (two vDSO clock reads).
  m.header = m.header_now();
  if (due(dec.joint_state)) {
    fill(s, m.header, m.m_joint);
    m.write(m.w_joint, &m.m_joint, m.joint, m.topics.joint_state.c_str());
    if (m.cfg.standard_topics) m.publish_joint_states_and_tf(s);
  }
  if (due(dec.controller_state)) {
    fill(s, m.header, m.m_ctrl);
    m.write(m.w_ctrl, &m.m_ctrl, m.ctrl, m.topics.controller_state.c_str());
  }
  if (due(dec.observer_state)) {
    fill(s, m.header, m.m_obs);
    m.write(m.w_obs, &m.m_obs, m.obs, m.topics.observer_state.c_str());
  }
  if (due(dec.loop_timing)) {
    fill(s, m.header, m.m_timing);
    m.write(m.w_timing, &m.m_timing, m.timing, m.topics.loop_timing.c_str());
  }
  // For α̇ and the diagnostics.
  const int n = clamp_joints(s.joints);
  std::copy_n(s.alpha.begin(), n, m.prev_alpha.begin());
  m.prev_t_ns = s.t_ns;
  m.have_prev = true;
  m.last_mode = static_cast<std::uint8_t>(s.mode);
  m.last_overruns = s.overruns;
  m.last_ring_drops = s.ring_drops;
  m.last_wake_latency_ns = s.wake_latency_ns;
  if (m.cfg.standard_topics && s.t_ns >= m.next_diag_ns) m.publish_diagnostics(s.t_ns);
}

void DdsTelemetry::on_event(const runtime::EventSample& e) {
  Impl& m = *impl_;
  m.header = m.header_now();
  const bool is_fault = e.fault != runtime::FaultClass::kNone;
  const bool is_mode = e.from != e.to;
  if (is_fault) {
    pedalwave_msg_dds__FaultEvent_ msg{};
    fill(e, m.header, ++m.fault_seq, msg);
    m.write(m.w_fault, &msg, m.fault_events, m.topics.fault_event.c_str());
    m.last_fault = e;
    ++m.faults_seen;
  }
  if (is_mode || !is_fault) {
    pedalwave_msg_dds__ModeEvent_ msg{};
    fill(e, m.header, ++m.mode_seq, msg);
    m.write(m.w_mode, &msg, m.mode_events, m.topics.mode_event.c_str());
  }
  m.resolve_outcomes(e);
  if (is_mode) m.last_mode = static_cast<std::uint8_t>(e.to);
  // A fault or a mode change is reported on /diagnostics at once.
  if (m.cfg.standard_topics && (is_fault || is_mode)) m.publish_diagnostics(e.t_ns);
}

TelemetryStats DdsTelemetry::stats() const {
  const Impl& m = *impl_;
  TelemetryStats st;
  st.joint_state = m.joint.get();
  st.controller_state = m.ctrl.get();
  st.observer_state = m.obs.get();
  st.loop_timing = m.timing.get();
  st.mode_events = m.mode_events.get();
  st.fault_events = m.fault_events.get();
  st.descriptions = m.descs.get();
  st.write_errors = m.errors.get();
  st.commands_accepted = m.accepted.get();
  st.commands_rejected = m.rejected.get();
  st.commands_executed = m.executed.get();
  st.commands_ignored = m.ignored.get();
  st.standard_messages = m.standard.get();
  return st;
}

const TelemetryConfig& DdsTelemetry::config() const { return impl_->cfg; }

int DdsTelemetry::joint_state_readers() const {
  dds_publication_matched_status_t st{};
  if (dds_get_publication_matched_status(impl_->w_joint, &st) < 0) return 0;
  return static_cast<int>(st.current_count);
}

}  // namespace pedalwave::telemetry
