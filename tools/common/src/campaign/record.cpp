// Exact one-line records and the one thread pool (campaign.hpp).
#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <mutex>
#include <stdexcept>
#include <thread>

#include "pedalwave/campaign/campaign.hpp"

namespace pedalwave::campaign {

void parallel_for(std::size_t n, int jobs, const std::function<void(std::size_t)>& f,
                  const std::function<void()>& done) {
  std::atomic<std::size_t> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  std::atomic<bool> stop{false};
  auto worker = [&]() {
    for (;;) {
      if (stop.load()) return;
      const std::size_t i = next.fetch_add(1);
      if (i >= n) return;
      try {
        f(i);
      } catch (...) {
        const std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
        stop = true;
        return;
      }
      if (done) done();
    }
  };
  const int threads = std::max(1, std::min<int>(jobs, static_cast<int>(std::max<std::size_t>(n, 1))));
  if (threads == 1) {
    worker();
  } else {
    std::vector<std::thread> pool;
    pool.reserve(static_cast<std::size_t>(threads));
    for (int i = 0; i < threads; ++i) pool.emplace_back(worker);
    for (std::thread& th : pool) th.join();
  }
  if (error) std::rethrow_exception(error);
}

int default_jobs() { return static_cast<int>(std::max(1u, std::thread::hardware_concurrency())); }

std::string hex(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%a", v);
  return buf;
}

std::string escape(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '\t': out += "%09"; break;
      case '\n': out += "%0A"; break;
      case '\r': out += "%0D"; break;
      case '%': out += "%25"; break;
      default: out += c;
    }
  }
  return out;
}

std::string unescape(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (text[i] != '%') {
      out += text[i];
      continue;
    }
    const std::string_view code = text.substr(i + 1, 2);
    if (code == "09") out += '\t';
    else if (code == "0A") out += '\n';
    else if (code == "0D") out += '\r';
    else if (code == "25") out += '%';
    else throw std::invalid_argument("escaped text: '%" + std::string(code) + "' at " + std::to_string(i) +
                                     ": expected %09, %0A, %0D or %25");
    i += 2;
  }
  return out;
}

std::string hash(std::string_view text) {
  std::uint64_t h = 14695981039346656037ull;  // FNV-1a 64 offset basis
  for (unsigned char c : text) {
    h ^= c;
    h *= 1099511628211ull;
  }
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h));
  return buf;
}

Record& Record::put(const std::string& key, double v) {
  fields_.emplace_back(key, hex(v));
  return *this;
}
Record& Record::put_int(const std::string& key, long long v) {
  fields_.emplace_back(key, std::to_string(v));
  return *this;
}
Record& Record::put_text(const std::string& key, std::string_view v) {
  fields_.emplace_back(key, escape(v));
  return *this;
}

std::string Record::line() const {
  std::string out;
  for (const auto& [k, v] : fields_) {
    if (!out.empty()) out += '\t';
    out += k;
    out += '=';
    out += v;
  }
  return out;
}

Record Record::parse(std::string_view line, std::string context) {
  Record r;
  r.context_ = std::move(context);
  std::size_t pos = 0;
  while (pos <= line.size() && !line.empty()) {
    const std::size_t end = std::min(line.find('\t', pos), line.size());
    const std::string_view field = line.substr(pos, end - pos);
    const std::size_t eq = field.find('=');
    if (eq == std::string_view::npos || eq == 0)
      throw std::invalid_argument(r.context_ + ": field '" + std::string(field.substr(0, 40)) +
                                  "': expected key=value");
    r.fields_.emplace_back(std::string(field.substr(0, eq)), std::string(field.substr(eq + 1)));
    pos = end + 1;
  }
  return r;
}

bool Record::has(const std::string& key) const {
  return std::any_of(fields_.begin(), fields_.end(), [&](const auto& f) { return f.first == key; });
}

const std::string& Record::raw(const std::string& key) const {
  for (const auto& f : fields_)
    if (f.first == key) return f.second;
  throw std::invalid_argument(context_ + ": " + key + ": expected the key (missing)");
}

double Record::number(const std::string& key) const {
  const std::string& v = raw(key);
  if (v == "nan") return std::nan("");
  errno = 0;
  char* end = nullptr;
  const double d = std::strtod(v.c_str(), &end);
  if (v.empty() || end != v.c_str() + v.size() || errno == ERANGE)
    throw std::invalid_argument(context_ + ": " + key + " = '" + v + "': expected a number");
  return d;
}

long long Record::integer(const std::string& key) const {
  const std::string& v = raw(key);
  errno = 0;
  char* end = nullptr;
  const long long x = std::strtoll(v.c_str(), &end, 10);
  if (v.empty() || end != v.c_str() + v.size() || errno == ERANGE)
    throw std::invalid_argument(context_ + ": " + key + " = '" + v + "': expected an integer");
  return x;
}

std::string Record::text(const std::string& key) const {
  const std::string& v = raw(key);
  try {
    return unescape(v);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(context_ + ": " + key + ": " + e.what());
  }
}

Backend parse_backend(const std::string& name) {
  if (name == "local") return Backend::local;
  if (name == "slurm") return Backend::slurm;
  throw std::invalid_argument("--backend " + name + ": expected local or slurm");
}

}  // namespace pedalwave::campaign
