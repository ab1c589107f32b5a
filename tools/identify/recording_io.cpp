// The recordings pedalwave_identify data reads besides pedalwave_sim's trajectory.csv: the robot's
// own telemetry, as an MCAP file (the daemon's telemetry.record, pedalwave_monitor --record
// run.mcap) or as the CSV recorder's per-topic files (pedalwave_monitor --record run.csv). Both are
// joined by cycle into the same Recording (recording.hpp).
#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>

#include "pedalwave/csv/csv.hpp"
#include "pedalwave/mcap/reader.hpp"
#include "pedalwave/mcap/ros2_decode.hpp"
#include "recording.hpp"

namespace pedalwave::identify {

namespace fs = std::filesystem;

namespace {

constexpr double kModeRunning = 4;  // pedalwave::runtime::Mode::kRunning (ControllerState.mode)
constexpr std::string_view kJointSuffix = "/pedalwave/joint_state";
constexpr std::string_view kControllerSuffix = "/pedalwave/controller_state";

bool ends_with(std::string_view s, std::string_view tail) {
  return s.size() >= tail.size() && s.substr(s.size() - tail.size()) == tail;
}

}  // namespace

Recording join_telemetry(const std::vector<JointRow>& joints, const std::vector<ControllerRow>& controller,
                         const std::string& source) {
  if (joints.empty()) throw std::runtime_error(source + ": no joint_state samples: expected a recording of a walk");
  std::map<long long, const ControllerRow*> by_seq;
  for (const ControllerRow& c : controller) {
    if (!by_seq.emplace(c.seq, &c).second)
      throw std::runtime_error(source + ": controller_state cycle " + std::to_string(c.seq) +
                               " recorded twice (the robot restarted during the recording?): expected one run");
  }
  std::vector<const JointRow*> rows;
  std::map<long long, bool> seen;
  for (const JointRow& j : joints) {
    if (!seen.emplace(j.seq, true).second)
      throw std::runtime_error(source + ": joint_state cycle " + std::to_string(j.seq) +
                               " recorded twice (the robot restarted during the recording?): expected one run");
    const auto it = by_seq.find(j.seq);
    if (it == by_seq.end() || it->second->mode != kModeRunning) continue;
    if (it->second->stamp_ns != j.stamp_ns)
      throw std::runtime_error(source + ": cycle " + std::to_string(j.seq) + ": joint_state stamp_ns " +
                               std::to_string(j.stamp_ns) + " and controller_state stamp_ns " +
                               std::to_string(it->second->stamp_ns) + ": expected the same cycle's wake-up time");
    rows.push_back(&j);
  }
  std::sort(rows.begin(), rows.end(), [](const JointRow* a, const JointRow* b) { return a->seq < b->seq; });
  if (rows.size() < 3)
    throw std::runtime_error(source + ": " + std::to_string(rows.size()) +
                             " cycles with both joint_state and controller_state in mode RUNNING: expected a walk "
                             "(≥ 3; the robot walking, state topics published every cycle: decimation_state: 1)");
  Recording r;
  r.source = source;
  r.joints = static_cast<int>(rows.front()->beta.size());
  if (r.joints < 1) throw std::runtime_error(source + ": joint_state with no joints");
  r.alpha.resize(static_cast<std::size_t>(r.joints));
  r.beta = r.beta_dot = r.u = r.alpha;
  for (const JointRow* j : rows) {
    const ControllerRow& c = *by_seq.at(j->seq);
    const auto J = static_cast<std::size_t>(r.joints);
    if (j->beta.size() != J || j->beta_dot.size() != J || j->alpha.size() != J || c.u.size() != J)
      throw std::runtime_error(source + ": cycle " + std::to_string(j->seq) + ": beta, beta_dot, alpha, u of " +
                               std::to_string(j->beta.size()) + ", " + std::to_string(j->beta_dot.size()) + ", " +
                               std::to_string(j->alpha.size()) + ", " + std::to_string(c.u.size()) +
                               " joints: expected " + std::to_string(J) + " each (the first cycle's)");
    r.t.push_back(j->t);
    r.cycle.push_back(j->seq);
    for (std::size_t i = 0; i < J; ++i) {
      r.beta[i].push_back(j->beta[i]);
      r.beta_dot[i].push_back(j->beta_dot[i]);
      r.alpha[i].push_back(j->alpha[i]);
      r.u[i].push_back(c.u[i]);
    }
  }
  // The samples on the controller's clock: t = t_0 + h k, h the control period (the smallest step
  // between consecutive cycles). A cycle the recording lost, or a period the loop skipped (an
  // overrun: t jumps by more than one period between consecutive cycles), leaves a gap in k; the
  // fit's windows do not span gaps.
  double h = HUGE_VAL;
  for (std::size_t k = 1; k < r.t.size(); ++k)
    if (r.t[k] > r.t[k - 1]) h = std::min(h, r.t[k] - r.t[k - 1]);
  if (!std::isfinite(h))
    throw std::runtime_error(source + ": controller time t does not advance: expected t rising with the cycle");
  r.cycle.clear();
  for (std::size_t k = 0; k < r.t.size(); ++k) {
    const long long index = std::llround((r.t[k] - r.t.front()) / h);
    const double expect = r.t.front() + h * static_cast<double>(index);
    if (!(std::abs(r.t[k] - expect) <= 1e-6 * h) || (k > 0 && index <= r.cycle.back()))
      throw std::runtime_error(source + ": cycle " + std::to_string(rows[k]->seq) + ": t = " + std::to_string(r.t[k]) +
                               " s: expected a whole number of control periods (" + std::to_string(h) +
                               " s) after the first sample's t = " + std::to_string(r.t.front()) + " s, rising");
    r.cycle.push_back(index);
  }
  // Contiguous: the same table as a trajectory.csv (no cycle column needed).
  if (static_cast<std::size_t>(r.cycle.back()) + 1 == r.cycle.size()) r.cycle.clear();
  return r;
}

// ---- MCAP ---------------------------------------------------------------------------------------------
Recording read_recording_mcap(const fs::path& file) {
  // A recording whose recorder died (no summary): its completed chunks are read, and said so.
  const mcap::Reader reader(file, mcap::ReaderOptions{.allow_unfinished = true});
  const std::string name = file.string();
  // The robot: the channel of <ns>/pedalwave/joint_state.
  std::vector<const mcap::ChannelRecord*> joint_channels;
  for (const auto& [id, c] : reader.channels())
    if (ends_with(c.topic, kJointSuffix)) joint_channels.push_back(&c);
  if (joint_channels.empty())
    throw std::runtime_error(name + ": no topic <ns>/pedalwave/joint_state (pedalwave/msg/JointState): expected the "
                             "robot's measured joint states (beta, beta_dot, alpha) as the daemon (telemetry.record) "
                             "or pedalwave_monitor --record run.mcap records them; the file has " + reader.topics_text());
  if (joint_channels.size() > 1) {
    std::string list;
    for (const auto* c : joint_channels) list += (list.empty() ? "" : ", ") + c->topic;
    throw std::runtime_error(name + ": several robots' joint_state topics (" + list + "): expected one robot's recording");
  }
  const mcap::ChannelRecord& jc = *joint_channels.front();
  const std::string ns = jc.topic.substr(0, jc.topic.size() - kJointSuffix.size());
  const std::string controller_topic = ns + std::string(kControllerSuffix);
  const mcap::ChannelRecord* cc = reader.channel(controller_topic);
  if (cc == nullptr)
    throw std::runtime_error(name + ": no topic " + controller_topic + " (pedalwave/msg/ControllerState): expected the "
                             "robot's commanded torques u beside its joint states; the file has " + reader.topics_text());
  auto decoder = [&](const mcap::ChannelRecord& c, const char* type) {
    const mcap::SchemaRecord* s = reader.schema_of(c);
    if (s == nullptr || s->encoding != "ros2msg" || c.message_encoding != "cdr")
      throw std::runtime_error(name + ": topic " + c.topic + ": schema " + (s ? "\"" + s->name + "\" (" + s->encoding + ")" : "none") +
                               ", message encoding \"" + c.message_encoding + "\": expected " + type +
                               " as a ros2msg schema with cdr messages");
    try {
      return mcap::Ros2MsgDecoder(s->name, s->data);
    } catch (const std::exception& e) {
      throw std::runtime_error(name + ": topic " + c.topic + ": " + e.what());
    }
  };
  const mcap::Ros2MsgDecoder jd = decoder(jc, "pedalwave/msg/JointState");
  const mcap::Ros2MsgDecoder cd = decoder(*cc, "pedalwave/msg/ControllerState");
  // The robot's description (transient-local: recorded once at the start), when present.
  double gear_ratio = 0, nominal_I_r = 0;
  std::vector<double> nominal_K;
  if (const mcap::ChannelRecord* dc = reader.channel(ns + "/pedalwave/robot_description")) {
    const mcap::Ros2MsgDecoder dd = decoder(*dc, "pedalwave/msg/RobotDescription");
    const std::vector<mcap::ChannelId> id{dc->id};
    for (const mcap::ReadMessage& m : reader.messages(id)) {
      try {
        const mcap::DecodedMessage d = dd.decode(m.data);
        gear_ratio = d.scalar("gear_ratio");
        nominal_I_r = d.scalar("rotor_inertia");
        nominal_K = d.at("spring_stiffness");
      } catch (const std::runtime_error& e) {
        throw std::runtime_error(name + ": byte " + std::to_string(m.offset) + ": " + dc->topic + ": " + e.what());
      }
    }
  }
  const std::vector<mcap::ChannelId> ids{jc.id, cc->id};
  std::vector<JointRow> joints;
  std::vector<ControllerRow> controller;
  for (const mcap::ReadMessage& m : reader.messages(ids)) {
    const bool is_joint = m.channel == jc.id;
    try {
      const mcap::DecodedMessage d = (is_joint ? jd : cd).decode(m.data);
      if (is_joint) {
        joints.push_back({static_cast<long long>(d.scalar("seq")), static_cast<long long>(d.scalar("stamp_ns")),
                          d.scalar("t"), d.at("beta"), d.at("beta_dot"), d.at("alpha")});
      } else {
        controller.push_back({static_cast<long long>(d.scalar("seq")), static_cast<long long>(d.scalar("stamp_ns")),
                              d.scalar("mode"), d.at("u")});
      }
    } catch (const std::runtime_error& e) {
      throw std::runtime_error(name + ": byte " + std::to_string(m.offset) + ": " + (is_joint ? jc.topic : cc->topic) +
                               " message " + std::to_string(m.sequence) + ": " + e.what());
    }
  }
  Recording r = join_telemetry(joints, controller, name);
  r.gear_ratio = gear_ratio;
  r.nominal_I_r = nominal_I_r;
  r.nominal_K = nominal_K;
  if (!reader.complete())
    r.notes.push_back(name + " ends without its summary and footer (the recorder did not close it): "
                             "read the " + std::to_string(reader.chunk_count()) + " whole chunk(s) before the end");
  return r;
}

// ---- the CSV recorder's files -------------------------------------------------------------------------
namespace {

// One CSV file of the recorder, read by the project's reader (csv::Table): seq and stamp_ns as
// exact integers (a nanosecond stamp is beyond a double's 2^53), the text columns the recorder
// writes (a mode's name, the robot's name and driver) as text, every other cell a number.
class RecorderCsv {
 public:
  explicit RecorderCsv(const fs::path& file, std::vector<std::string> integer_columns)
      : table_(csv::Table::read(file, {.integer_columns = std::move(integer_columns),
                                        .text_columns = {"mode_name", "name", "driver"}})) {}
  [[nodiscard]] std::size_t rows() const { return table_.rows(); }
  [[nodiscard]] bool has(const std::string& c) const { return table_.has(c); }
  [[nodiscard]] double number(std::size_t row, const std::string& column) const { return table_.column(column)[row]; }
  [[nodiscard]] long long integer(std::size_t row, const std::string& column) const {
    return table_.integers(column)[row];
  }
  // Columns <prefix>_1, <prefix>_2, … (1-based) present in the header.
  [[nodiscard]] int count(const std::string& prefix) const {
    int n = 0;
    while (has(prefix + "_" + std::to_string(n + 1))) ++n;
    return n;
  }
  // Columns <prefix>_1 … <prefix>_n of a row, as the 0-based array [0, n).
  [[nodiscard]] std::vector<double> joints(std::size_t row, const std::string& prefix, int n) const {
    std::vector<double> v;
    for (int i = 1; i <= n; ++i) v.push_back(number(row, prefix + "_" + std::to_string(i)));
    return v;
  }
  void require(const std::string& column, const std::string& what) const {
    if (!has(column))
      throw std::runtime_error(table_.source() + ": column " + column + " missing: expected " + what);
  }

 private:
  csv::Table table_;
};

}  // namespace

Recording read_recorder_csv(const fs::path& joint_state_csv, const fs::path& controller_state_csv) {
  const std::string what_js = "the CSV recorder's joint_state columns seq, stamp_ns, t, beta_j, beta_dot_j, alpha_j";
  const std::string what_cs = "the CSV recorder's controller_state columns seq, stamp_ns, mode, u_j";
  // seq and stamp_ns are checked while reading (exact integers: the table names a missing one).
  const auto read = [](const fs::path& file, const std::string& what) {
    try {
      return RecorderCsv(file, {"seq", "stamp_ns"});
    } catch (const csv::Error& e) {
      throw std::runtime_error(std::string(e.what()) + " (reading " + what + ")");
    }
  };
  const RecorderCsv js = read(joint_state_csv, what_js), cs = read(controller_state_csv, what_cs);
  for (const char* c : {"t", "beta_1", "beta_dot_1", "alpha_1"}) js.require(c, what_js);
  for (const char* c : {"mode", "u_1"}) cs.require(c, what_cs);
  const int nj = js.count("beta"), nc = cs.count("u");
  std::vector<JointRow> joints;
  std::vector<ControllerRow> controller;
  for (std::size_t k = 0; k < js.rows(); ++k)
    joints.push_back({js.integer(k, "seq"), js.integer(k, "stamp_ns"), js.number(k, "t"), js.joints(k, "beta", nj),
                      js.joints(k, "beta_dot", nj), js.joints(k, "alpha", nj)});
  for (std::size_t k = 0; k < cs.rows(); ++k)
    controller.push_back({cs.integer(k, "seq"), cs.integer(k, "stamp_ns"), cs.number(k, "mode"), cs.joints(k, "u", nc)});
  Recording r = join_telemetry(joints, controller, joint_state_csv.string() + " + " + controller_state_csv.filename().string());
  // The robot's description beside them (run.robot_description.csv), when recorded.
  const std::string js_name = joint_state_csv.string();
  const fs::path desc = js_name.substr(0, js_name.size() - std::string_view(".joint_state.csv").size()) +
                        ".robot_description.csv";
  if (ends_with(js_name, ".joint_state.csv") && fs::exists(desc) && fs::file_size(desc) > 0) {
    const RecorderCsv d(desc, {});
    if (d.rows() > 0 && d.has("gear_ratio") && d.has("rotor_inertia")) {
      const std::size_t last = d.rows() - 1;
      r.gear_ratio = d.number(last, "gear_ratio");
      r.nominal_I_r = d.number(last, "rotor_inertia");
      r.nominal_K = d.joints(last, "spring_stiffness", d.count("spring_stiffness"));
    }
  }
  return r;
}

// ---- any of them -------------------------------------------------------------------------------------
Recording read_recording(const fs::path& file) {
  const std::string s = file.string();
  auto ends = [&](std::string_view tail) {
    return s.size() >= tail.size() &&
           std::equal(tail.begin(), tail.end(), s.end() - static_cast<std::ptrdiff_t>(tail.size()),
                      [](char a, char b) { return std::tolower(static_cast<unsigned char>(a)) == b; });
  };
  if (ends(".mcap") || mcap::has_mcap_magic(file)) return read_recording_mcap(file);
  if (ends(".joint_state.csv")) {
    const std::string stem = s.substr(0, s.size() - std::string_view(".joint_state.csv").size());
    return read_recorder_csv(file, stem + ".controller_state.csv");
  }
  if (!fs::exists(file)) {  // run.csv given: the recorder wrote run.<topic>.csv
    const std::string stem = ends(".csv") ? s.substr(0, s.size() - 4) : s;
    if (fs::exists(stem + ".joint_state.csv"))
      return read_recorder_csv(stem + ".joint_state.csv", stem + ".controller_state.csv");
  }
  return read_recording_csv(file);
}

}  // namespace pedalwave::identify
