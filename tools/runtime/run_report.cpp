#include "run_report.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <string_view>

#include "pedalwave/toolkit/format.hpp"

namespace pedalwave::app {

namespace {

// Length of the valid UTF-8 sequence starting at s[i], 0 if it is not one.
std::size_t utf8_length(std::string_view s, std::size_t i) {
  const auto b = static_cast<unsigned char>(s[i]);
  std::size_t n = 0;
  unsigned min = 0;
  if (b < 0x80) return 1;
  if (b >= 0xC2 && b <= 0xDF) n = 2, min = 0x80;
  else if (b >= 0xE0 && b <= 0xEF) n = 3, min = 0x800;
  else if (b >= 0xF0 && b <= 0xF4) n = 4, min = 0x10000;
  else return 0;
  if (i + n > s.size()) return 0;
  unsigned cp = b & (0x7Fu >> n);
  for (std::size_t k = 1; k < n; ++k) {
    const auto c = static_cast<unsigned char>(s[i + k]);
    if ((c & 0xC0) != 0x80) return 0;
    cp = (cp << 6) | (c & 0x3F);
  }
  if (cp < min || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return 0;
  return n;
}

// A minimal streaming JSON writer: objects, arrays, keys, commas in the right places.
class Json {
 public:
  explicit Json(std::ostream& out) : out_(out) {}
  Json& open(char c) {
    sep();
    out_ << c;
    first_ = true;
    return *this;
  }
  Json& close(char c) {
    out_ << c;
    first_ = false;
    return *this;
  }
  Json& key(std::string_view k) {
    sep();
    out_ << json_string(k) << ':';
    first_ = true;  // the value follows without a comma
    return *this;
  }
  Json& raw(const std::string& v) {
    sep();
    out_ << v;
    return *this;
  }
  Json& str(std::string_view v) { return raw(json_string(v)); }
  Json& num(double v) { return raw(json_number(v)); }
  Json& integer(long long v) { return raw(std::to_string(v)); }
  Json& uint(unsigned long long v) { return raw(std::to_string(v)); }
  Json& boolean(bool v) { return raw(v ? "true" : "false"); }
  Json& joint(std::int16_t j) { return j >= 0 ? integer(j + 1) : raw("null"); }  // 1-based

 private:
  void sep() {
    if (!first_) out_ << ',';
    first_ = false;
  }
  std::ostream& out_;
  bool first_ = true;
};

double us(std::int64_t ns) { return static_cast<double>(ns) / 1e3; }  // [µs], correctly rounded

void histogram(Json& j, const char* name, const runtime::LatencyHistogram& h) {
  using H = runtime::LatencyHistogram;
  j.key(name).open('{');
  j.key("count").uint(h.count());
  j.key("min").num(us(h.min()));
  j.key("p50").num(us(h.percentile(0.5)));
  j.key("p90").num(us(h.percentile(0.9)));
  j.key("p99").num(us(h.percentile(0.99)));
  j.key("p999").num(us(h.percentile(0.999)));
  j.key("max").num(us(h.max()));
  j.key("overflows").uint(h.overflows());
  j.key("bins").open('[');
  for (std::size_t b = 0; b < H::kBins; ++b) {
    if (h.bin_count(b) == 0) continue;
    const std::int64_t hi = b + 1 < H::kBins ? H::bin_upper(b) : h.max();
    j.open('[').num(us(H::bin_lower(b))).num(us(hi)).uint(h.bin_count(b)).close(']');
  }
  j.close(']');
  j.close('}');
}

}  // namespace

std::string json_string(std::string_view s) {
  std::string out = "\"";
  for (std::size_t i = 0; i < s.size();) {
    const char c = s[i];
    const auto u = static_cast<unsigned char>(c);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (c == '\n') {
      out += "\\n";
    } else if (c == '\t') {
      out += "\\t";
    } else if (c == '\r') {
      out += "\\r";
    } else if (u < 0x20 || u == 0x7F) {
      char b[8];
      std::snprintf(b, sizeof b, "\\u%04x", u);
      out += b;
    } else if (u >= 0x80) {
      const std::size_t n = utf8_length(s, i);
      if (n == 0) {
        out += "\\ufffd";
        ++i;
        continue;
      }
      out.append(s.substr(i, n));
      i += n;
      continue;
    } else {
      out += c;
    }
    ++i;
  }
  out += '"';
  return out;
}

std::string json_number(double v) { return std::isfinite(v) ? toolkit::exact(v) : "null"; }

void write_run_report(std::ostream& out, const RunReportInput& in) {
  const config::DaemonConfig& cfg = in.cfg;
  const runtime::RunResult& r = in.run;
  const runtime::LoopMetrics& m = in.metrics;
  Json j(out);
  j.open('{');
  j.key("name").str(cfg.name);
  j.key("config").str(cfg.source);
  j.key("driver").str(config::to_string(cfg.driver.kind));
  j.key("rate_hz").num(cfg.runtime.rt.rate_hz);
  j.key("duration_s").num(static_cast<double>(r.cycles) / cfg.runtime.rt.rate_hz);

  j.key("exit").open('{');
  j.key("reason").str(runtime::to_string(r.reason));
  j.key("final_mode").str(runtime::to_string(r.final_mode));
  j.key("fault").str(runtime::to_string(r.fault));
  j.key("joint").joint(r.fault != runtime::FaultClass::kNone ? r.fault_joint : std::int16_t{-1});
  j.key("signal").integer(r.signal);
  j.close('}');

  j.key("events").open('[');
  for (const runtime::RunEvent& e : in.events.events()) {
    const runtime::EventSample& s = e.sample;
    j.open('{');
    j.key("t").num(in.events.seconds(s));
    j.key("cycle").uint(s.seq);
    j.key("kind").str(runtime::to_string(e.kind));
    j.key("class").str(runtime::to_string(s.fault));
    j.key("severity").str(runtime::to_string(s.severity));
    j.key("joint").joint(s.joint);
    j.key("value").num(s.value);
    j.key("threshold").num(s.threshold);
    j.key("text").str(s.text.data());
    j.key("reaction").str(runtime::to_string(e.reaction));
    j.close('}');
  }
  j.close(']');
  j.key("events_dropped").uint(in.events.dropped());

  j.key("loop").open('{');
  j.key("cycles").uint(m.cycles);
  j.key("overruns").uint(m.overruns);
  j.key("skipped_periods").uint(m.skipped_periods);
  j.key("max_skipped").uint(m.max_skipped);
  j.key("cycle_drops").uint(r.cycle_drops);
  j.key("event_drops").uint(r.event_drops);
  j.close('}');

  j.key("timing_us").open('{');
  histogram(j, "wake", m.wake);
  histogram(j, "read", m.read);
  histogram(j, "observe", m.observe);
  histogram(j, "control", m.control);
  histogram(j, "write", m.write);
  histogram(j, "cycle", m.cycle);
  j.close('}');

  const drivers::DriverCounters& c = in.counters;
  j.key("driver_counters").open('{');
  j.key("frames_tx").uint(c.frames_tx);
  j.key("frames_rx").uint(c.frames_rx);
  j.key("missing").uint(c.missing);
  j.key("late").uint(c.late);
  j.key("late_used").uint(c.late_used);
  j.key("duplicate").uint(c.duplicate);
  j.key("out_of_order").uint(c.out_of_order);
  j.key("checksum").uint(c.checksum);
  j.key("malformed").uint(c.malformed);
  j.key("bus_errors").uint(c.bus_errors);
  j.key("tx_dropped").uint(c.tx_dropped);
  j.key("rx_dropped").uint(c.rx_dropped);
  j.key("rx_silence_max_s").num(1e-9 * static_cast<double>(c.rx_silence_max_ns));
  j.close('}');

  j.key("settings").open('{');
  j.key("stale_timeout_s").num(cfg.runtime.stale_timeout);
  j.key("read_budget").num(cfg.runtime.read_budget);
  j.key("observer").boolean(in.observer);
  j.key("telemetry").boolean(in.telemetry);
  j.close('}');
  j.close('}');
  out << '\n';
}

}  // namespace pedalwave::app
