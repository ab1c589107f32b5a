#include "pedalwave/telemetry/dds_telemetry.hpp"

#include <spdlog/spdlog.h>

#include <atomic>
#include <ctime>
#include <thread>

#include "convert.hpp"
#include "domain.hpp"
#include "pedalwave/telemetry/command_validation.hpp"
#include "pedalwave/telemetry/names.hpp"

namespace pedalwave::telemetry {

using namespace detail;

namespace {

std::int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
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
  dds_entity_t r_cmd = 0;
  dds_entity_t waitset = 0, cmd_cond = 0, stop_guard = 0;
  std::thread cmd_thread;

  Counter joint, ctrl, obs, timing, mode_events, fault_events, descs, errors, accepted, rejected;

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

  void publish_ack(const runtime::OperatorCommand& c, const CommandDecision& d) {
    pedalwave_msg_dds__CommandAck_ ack{};
    ack.id = c.id;
    ack.kind = static_cast<std::uint8_t>(c.kind);
    ack.accepted = d.accepted;
    ack.stamp_ns = monotonic_ns();
    copy_bounded(ack.reason, d.reason.c_str());
    Counter dummy;
    write(w_ack, &ack, dummy, kTopicCommandAck);
  }

  void handle_command(const pedalwave_msg_dds__OperatorCommand_& m) {
    const runtime::OperatorCommand c = to_command(m);
    CommandDecision d = validate_command(c, cfg);
    if (d.accepted && !handler) {
      d = {false, "no command handler installed (telemetry-only process)"};
    } else if (d.accepted && !handler(c)) {
      d = {false, "runtime command mailbox full; retry"};
    }
    (d.accepted ? accepted : rejected).add();
    if (d.accepted) {
      spdlog::info("telemetry: command {} id {} from \"{}\" accepted", command_kind_name(m.kind),
                   m.id, m.sender);
    } else {
      spdlog::warn("telemetry: command {} id {} from \"{}\" rejected: {}",
                   command_kind_name(m.kind), m.id, m.sender, d.reason);
    }
    publish_ack(c, d);
  }

  void command_loop() {
    constexpr std::uint32_t kBatch = 16;
    std::array<dds_attach_t, 2> triggered{};
    for (;;) {
      const dds_return_t n =
          dds_waitset_wait(waitset, triggered.data(), triggered.size(), DDS_INFINITY);
      bool stop = false;
      dds_read_guardcondition(stop_guard, &stop);
      if (stop) return;
      if (n < 0) {
        spdlog::error("telemetry: command waitset failed: {}", dds_strretcode(n));
        return;
      }
      // Take everything that arrived (loaned samples, returned after handling).
      for (;;) {
        std::array<void*, kBatch> buf{};
        std::array<dds_sample_info_t, kBatch> info{};
        const dds_return_t got = dds_take(cmd_cond, buf.data(), info.data(), kBatch, kBatch);
        if (got <= 0) break;
        for (dds_return_t i = 0; i < got; ++i) {
          if (info[static_cast<std::size_t>(i)].valid_data) {
            handle_command(*static_cast<const pedalwave_msg_dds__OperatorCommand_*>(
                buf[static_cast<std::size_t>(i)]));
          }
        }
        dds_return_loan(cmd_cond, buf.data(), got);
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
  m.domain = acquire_domain(config.domain());
  m.participant = Entity(check(
      dds_create_participant(static_cast<dds_domainid_t>(config.domain_id), nullptr, nullptr),
      "dds_create_participant"));

  m.w_joint = m.make_writer(&pedalwave_msg_dds__JointState__desc, kTopicJointState,
                            QosClass::kState);
  m.w_ctrl = m.make_writer(&pedalwave_msg_dds__ControllerState__desc, kTopicControllerState,
                           QosClass::kState);
  m.w_obs = m.make_writer(&pedalwave_msg_dds__ObserverState__desc, kTopicObserverState,
                          QosClass::kState);
  m.w_timing = m.make_writer(&pedalwave_msg_dds__LoopTiming__desc, kTopicLoopTiming,
                             QosClass::kState);
  m.w_mode = m.make_writer(&pedalwave_msg_dds__ModeEvent__desc, kTopicModeEvent, QosClass::kEvent);
  m.w_fault =
      m.make_writer(&pedalwave_msg_dds__FaultEvent__desc, kTopicFaultEvent, QosClass::kEvent);
  m.w_desc = m.make_writer(&pedalwave_msg_dds__RobotDescription__desc, kTopicDescription,
                           QosClass::kDescription);
  m.w_ack =
      m.make_writer(&pedalwave_msg_dds__CommandAck__desc, kTopicCommandAck, QosClass::kCommand);

  // Command reader + waitset (read condition on any new sample, guard condition to stop).
  const dds_entity_t cmd_topic =
      m.make_topic(&pedalwave_msg_dds__OperatorCommand__desc, kTopicCommand);
  dds_qos_t* q = make_qos(QosClass::kCommand);
  m.r_cmd = check(dds_create_reader(m.participant.get(), cmd_topic, q, nullptr),
                  "dds_create_reader(command)");
  dds_delete_qos(q);
  m.cmd_cond = check(dds_create_readcondition(m.r_cmd, DDS_ANY_STATE), "dds_create_readcondition");
  m.stop_guard =
      check(dds_create_guardcondition(m.participant.get()), "dds_create_guardcondition");
  m.waitset = check(dds_create_waitset(m.participant.get()), "dds_create_waitset");
  check(dds_waitset_attach(m.waitset, m.cmd_cond, 0), "dds_waitset_attach");
  check(dds_waitset_attach(m.waitset, m.stop_guard, 1), "dds_waitset_attach");
  m.cmd_thread = std::thread([this] { impl_->command_loop(); });

  spdlog::info("telemetry: DDS domain {} on \"{}\", commands {}", config.domain_id,
               config.interface, config.enable_commands ? "enabled" : "disabled (e-stop only)");
}

DdsTelemetry::~DdsTelemetry() {
  if (impl_->cmd_thread.joinable()) {
    dds_set_guardcondition(impl_->stop_guard, true);
    impl_->cmd_thread.join();
  }
  impl_->participant.reset();  // deletes topics, writers, reader, conditions, waitset
}

void DdsTelemetry::on_description(const runtime::RobotDescription& d) {
  pedalwave_msg_dds__RobotDescription_ msg{};
  fill(d, impl_->cfg.decimation, msg);
  impl_->write(impl_->w_desc, &msg, impl_->descs, kTopicDescription);
}

void DdsTelemetry::on_cycle(const runtime::CycleSample& s) {
  Impl& m = *impl_;
  const Decimation& dec = m.cfg.decimation;
  const auto due = [&s](int k) { return s.seq % static_cast<std::uint64_t>(k) == 0; };
  if (due(dec.joint_state)) {
    fill(s, m.m_joint);
    m.write(m.w_joint, &m.m_joint, m.joint, kTopicJointState);
  }
  if (due(dec.controller_state)) {
    fill(s, m.m_ctrl);
    m.write(m.w_ctrl, &m.m_ctrl, m.ctrl, kTopicControllerState);
  }
  if (due(dec.observer_state)) {
    fill(s, m.m_obs);
    m.write(m.w_obs, &m.m_obs, m.obs, kTopicObserverState);
  }
  if (due(dec.loop_timing)) {
    fill(s, m.m_timing);
    m.write(m.w_timing, &m.m_timing, m.timing, kTopicLoopTiming);
  }
}

void DdsTelemetry::on_event(const runtime::EventSample& e) {
  Impl& m = *impl_;
  const bool is_fault = e.fault != runtime::FaultClass::kNone;
  const bool is_mode = e.from != e.to;
  if (is_fault) {
    pedalwave_msg_dds__FaultEvent_ msg{};
    fill(e, msg);
    m.write(m.w_fault, &msg, m.fault_events, kTopicFaultEvent);
  }
  if (is_mode || !is_fault) {
    pedalwave_msg_dds__ModeEvent_ msg{};
    fill(e, msg);
    m.write(m.w_mode, &msg, m.mode_events, kTopicModeEvent);
  }
}

TelemetryStats DdsTelemetry::stats() const {
  const Impl& m = *impl_;
  return {m.joint.get(),        m.ctrl.get(),         m.obs.get(),   m.timing.get(),
          m.mode_events.get(),  m.fault_events.get(), m.descs.get(), m.errors.get(),
          m.accepted.get(),     m.rejected.get()};
}

const TelemetryConfig& DdsTelemetry::config() const { return impl_->cfg; }

int DdsTelemetry::joint_state_readers() const {
  dds_publication_matched_status_t st{};
  if (dds_get_publication_matched_status(impl_->w_joint, &st) < 0) return 0;
  return static_cast<int>(st.current_count);
}

}  // namespace pedalwave::telemetry
