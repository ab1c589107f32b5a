#include "pedalwave/csv/csv.hpp"

#include <cerrno>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <limits>
#include <set>
#include <sstream>
#include <system_error>

namespace pedalwave::csv {

// ---- numbers -----------------------------------------------------------------------------------

void append_number(std::string& out, double v, Numbers numbers) {
  if (std::isnan(v)) {
    out += (numbers == Numbers::kFixed && std::signbit(v)) ? "-nan" : "nan";
    return;
  }
  if (std::isinf(v)) {
    out += v > 0 ? "inf" : "-inf";
    return;
  }
  char buf[64];
  if (numbers == Numbers::kShortest) {
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    out.append(buf, r.ptr);
    return;
  }
  // kFixed: the shortest digits in exponent form tell the decimal exponent; from 1e-4 up to
  // 1e16 the same digits are written in fixed form instead.
  const auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::scientific);
  const char* e = r.ptr;
  while (e != buf && *(e - 1) != 'e') --e;
  int exponent = 0;
  std::from_chars(*e == '+' ? e + 1 : e, r.ptr, exponent);
  if (exponent < -4 || exponent >= 16) {
    out.append(buf, r.ptr);
    return;
  }
  const auto f = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::fixed);
  out.append(buf, f.ptr);
}

// ---- writer ------------------------------------------------------------------------------------

namespace {

std::string named(const std::filesystem::path& p) { return "CSV '" + p.string() + "'"; }

void check_header(const std::filesystem::path& path, const std::vector<std::string>& header) {
  if (header.empty()) throw Error(named(path) + ": the header names no column");
  std::set<std::string_view> seen;
  for (std::size_t i = 0; i < header.size(); ++i) {
    const std::string& n = header[i];
    const std::string col = "column " + std::to_string(i + 1) + " ('" + n + "')";
    if (n.empty()) throw Error(named(path) + ": column " + std::to_string(i + 1) + " has an empty name");
    if (n.find_first_of(",\"\r\n") != std::string::npos || (i == 0 && n[0] == '#')) {
      throw Error(named(path) + ": " + col + " contains ',', '\"', a line break or a leading '#'");
    }
    if (!seen.insert(n).second) throw Error(named(path) + ": " + col + " is named twice");
  }
}

void append_quoted(std::string& line, std::string_view t) {
  line += '"';
  for (const char c : t) {
    if (c == '"') line += '"';
    line += c;
  }
  line += '"';
}

void append_text(std::string& line, std::string_view t) {
  if (t.find_first_of(",\"\r\n") == std::string_view::npos) {
    line += t;
    return;
  }
  append_quoted(line, t);
}

}  // namespace

void Writer::open() {
  std::error_code ec;
  if (options_.create_folders && path_.has_parent_path()) {
    std::filesystem::create_directories(path_.parent_path(), ec);
  }
  errno = 0;
  out_.open(path_, std::ios::binary | std::ios::trunc);
  if (!out_) {
    const int err = errno;
    throw Error(named(path_) + ": cannot open for writing" +
                (err != 0 ? std::string(": ") + std::strerror(err) : std::string()));
  }
}

Writer::Writer(const std::filesystem::path& path, std::vector<std::string> header, Options options)
    : path_(path), options_(options) {
  check_header(path_, header);
  open();
  this->header(std::move(header));
}

Writer::Writer(const std::filesystem::path& path, Options options, Late) : path_(path), options_(options) {
  open();
}

Writer Writer::header_later(const std::filesystem::path& path, Options options) {
  return Writer(path, options, Late{});
}

void Writer::header(std::vector<std::string> names) {
  if (!header_.empty()) throw Error(named(path_) + ": the header is written already");
  check_header(path_, names);
  header_ = std::move(names);
  line_.clear();
  for (std::size_t i = 0; i < header_.size(); ++i) {
    if (i) line_ += ',';
    line_ += header_[i];
  }
  line_ += '\n';
  out_.write(line_.data(), static_cast<std::streamsize>(line_.size()));
  line_.clear();
  cells_ = 0;
}

void Writer::comment(std::string_view text) {
  std::size_t start = 0;
  while (true) {
    const std::size_t nl = text.find('\n', start);
    const std::string_view l = text.substr(start, nl == std::string_view::npos ? std::string_view::npos : nl - start);
    out_ << "# " << l << '\n';
    if (nl == std::string_view::npos) break;
    start = nl + 1;
  }
}

void Writer::check_count(std::size_t n) {
  if (n != header_.size()) {
    line_.clear();
    cells_ = 0;
    if (header_.empty()) throw Error(named(path_) + ": a row before the header");
    throw Error(named(path_) + ": row " + std::to_string(rows_ + 1) + " has " + std::to_string(n) +
                " values but the header names " + std::to_string(header_.size()) + " columns");
  }
}

void Writer::begin_cell() {
  if (cells_++ != 0) line_ += ',';
}

Writer& Writer::number(double v) {
  begin_cell();
  append_number(line_, v, options_.numbers);
  return *this;
}

Writer& Writer::append_integer(long long v) {
  begin_cell();
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  line_.append(buf, r.ptr);
  return *this;
}

Writer& Writer::append_unsigned(unsigned long long v) {
  begin_cell();
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  line_.append(buf, r.ptr);
  return *this;
}

Writer& Writer::text(std::string_view t) {
  begin_cell();
  append_text(line_, t);
  return *this;
}

Writer& Writer::quoted(std::string_view t) {
  begin_cell();
  append_quoted(line_, t);
  return *this;
}

Writer& Writer::empty() {
  begin_cell();
  return *this;
}

void Writer::end_row() {
  check_count(cells_);
  line_ += '\n';
  out_.write(line_.data(), static_cast<std::streamsize>(line_.size()));
  line_.clear();
  cells_ = 0;
  ++rows_;
}

void Writer::row(std::span<const double> values) {
  check_count(values.size());
  line_.clear();
  cells_ = 0;
  for (const double v : values) number(v);
  end_row();
}

void Writer::row(std::span<const Cell> cells) {
  check_count(cells.size());
  line_.clear();
  cells_ = 0;
  for (const Cell& c : cells) {
    if (c.is_text) text(c.text);
    else number(c.number);
  }
  end_row();
}

void Writer::flush() { out_.flush(); }

void Writer::close() {
  if (!out_.is_open()) return;
  out_.flush();
  const bool ok = static_cast<bool>(out_);
  out_.close();
  if (!ok) throw Error(named(path_) + ": write failed (disk full or file removed?)");
}

Writer::~Writer() {
  try {
    close();
  } catch (...) {  // NOLINT(bugprone-empty-catch): destructors must not throw; close() reports
  }
}

// ---- reader ------------------------------------------------------------------------------------

namespace {

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

bool parse_number(std::string_view f, double& out) {
  if (!f.empty() && f.front() == '+') f.remove_prefix(1);
  if (f.empty()) return false;
  // from_chars accepts "nan", "inf", "infinity" (any case) and "-inf"
  const auto r = std::from_chars(f.data(), f.data() + f.size(), out);
  if (r.ec == std::errc::result_out_of_range) {
    // overflow/underflow: fall back to strtod semantics (±Inf or a denormal/zero)
    const std::string s(f);
    char* end = nullptr;
    out = std::strtod(s.c_str(), &end);
    return end == s.c_str() + s.size();
  }
  return r.ec == std::errc() && r.ptr == f.data() + f.size();
}

enum class IntegerRead { kOk, kNotInteger, kOutOfRange };

IntegerRead parse_integer(std::string_view f, std::int64_t& out) {
  if (!f.empty() && f.front() == '+') f.remove_prefix(1);
  if (f.empty()) return IntegerRead::kNotInteger;
  const auto r = std::from_chars(f.data(), f.data() + f.size(), out);
  if (r.ec == std::errc::result_out_of_range && r.ptr == f.data() + f.size()) return IntegerRead::kOutOfRange;
  return r.ec == std::errc() && r.ptr == f.data() + f.size() ? IntegerRead::kOk : IntegerRead::kNotInteger;
}

// Splits at the commas outside quotes; a quoted field loses its quotes and "" becomes ".
// `storage` keeps the unquoted text the views of such fields point into (a deque: appending
// does not move its strings).
void split(std::string_view line, std::vector<std::string_view>& fields, std::deque<std::string>& storage) {
  fields.clear();
  storage.clear();
  std::size_t start = 0;
  while (true) {
    std::size_t c = start;
    bool quoted = false;
    while (c < line.size() && (quoted || line[c] != ',')) {
      if (line[c] == '"') quoted = !quoted;
      ++c;
    }
    std::string_view f = trim(line.substr(start, c - start));
    if (f.size() >= 2 && f.front() == '"' && f.back() == '"') {
      std::string& u = storage.emplace_back();
      for (std::size_t i = 1; i + 1 < f.size(); ++i) {
        u += f[i];
        if (f[i] == '"' && i + 2 < f.size() && f[i + 1] == '"') ++i;
      }
      f = u;
    }
    fields.push_back(f);
    if (c >= line.size()) break;
    start = c + 1;
  }
}

}  // namespace
Table Table::parse(std::string_view text, std::string source, ReadOptions options) {
  Table t;
  t.source_ = std::move(source);
  std::vector<std::string_view> fields;
  std::deque<std::string> storage;
  std::size_t line_no = 0;
  std::size_t pos = 0;
  bool have_header = false;
  while (pos < text.size()) {
    const std::size_t nl = text.find('\n', pos);
    std::string_view line = text.substr(pos, nl == std::string_view::npos ? std::string_view::npos : nl - pos);
    pos = nl == std::string_view::npos ? text.size() : nl + 1;
    ++line_no;
    const std::string_view tl = trim(line);
    if (tl.empty()) continue;
    if (tl.front() == '#') {
      std::string_view c = tl.substr(1);
      if (!c.empty() && c.front() == ' ') c.remove_prefix(1);
      t.comments_.emplace_back(c);
      continue;
    }
    const std::string where = t.source_ + ":" + std::to_string(line_no);
    split(tl, fields, storage);
    if (!have_header) {
      std::set<std::string_view> seen;
      for (std::size_t i = 0; i < fields.size(); ++i) {
        const std::string_view n = fields[i];
        if (n.empty()) throw Error(where + ": header column " + std::to_string(i + 1) + " has an empty name");
        if (!seen.insert(n).second) {
          throw Error(where + ": header column " + std::to_string(i + 1) + " ('" + std::string(n) + "') is named twice");
        }
        t.names_.emplace_back(n);
      }
      t.columns_.resize(t.names_.size());
      t.kinds_.assign(t.names_.size(), Kind::kNumber);
      t.integers_.resize(t.names_.size());
      t.texts_.resize(t.names_.size());
      for (const std::string& n : options.integer_columns) {
        const auto it = std::find(t.names_.begin(), t.names_.end(), n);
        if (it == t.names_.end()) {
          std::string avail;
          for (const auto& m : t.names_) avail += (avail.empty() ? "" : ", ") + m;
          throw Error(where + ": no column '" + n + "' (columns: " + avail + "): expected it, as integers");
        }
        t.kinds_[static_cast<std::size_t>(it - t.names_.begin())] = Kind::kInteger;
      }
      for (const std::string& n : options.text_columns) {
        const auto it = std::find(t.names_.begin(), t.names_.end(), n);
        if (it != t.names_.end()) t.kinds_[static_cast<std::size_t>(it - t.names_.begin())] = Kind::kText;
      }
      have_header = true;
      continue;
    }
    if (fields.size() != t.names_.size()) {
      const std::string what = where + ": row has " + std::to_string(fields.size()) +
                               " fields but the header names " + std::to_string(t.names_.size()) + " columns";
      if (!options.skip_ragged) throw Error(what);
      t.skipped_.push_back(what + ": skipped");
      continue;
    }
    for (std::size_t i = 0; i < fields.size(); ++i) {
      if (t.kinds_[i] == Kind::kText) {
        t.texts_[i].emplace_back(fields[i]);
        t.columns_[i].push_back(std::numeric_limits<double>::quiet_NaN());
        continue;
      }
      if (t.kinds_[i] == Kind::kInteger) {
        std::int64_t n = 0;
        const IntegerRead r = parse_integer(fields[i], n);
        if (r != IntegerRead::kOk) {
          throw Error(where + ": column " + std::to_string(i + 1) + " ('" + t.names_[i] + "'): '" +
                      std::string(fields[i]) + "' is " +
                      (r == IntegerRead::kOutOfRange ? "beyond the 64-bit integers" : "not an integer") +
                      ": expected a whole number in [-9223372036854775808, 9223372036854775807]");
        }
        t.integers_[i].push_back(n);
        t.columns_[i].push_back(static_cast<double>(n));
        continue;
      }
      double v = 0.0;
      if (!parse_number(fields[i], v)) {
        if (options.text_as_nan) {
          t.columns_[i].push_back(std::numeric_limits<double>::quiet_NaN());
          continue;
        }
        throw Error(where + ": column " + std::to_string(i + 1) + " ('" + t.names_[i] + "'): '" +
                       std::string(fields[i]) + "' is not a number");
      }
      t.columns_[i].push_back(v);
    }
  }
  if (!have_header) throw Error(t.source_ + ": no header line (expected the column names)");
  return t;
}

Table Table::read(const std::filesystem::path& path, ReadOptions options) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw Error(path.string() + ": cannot open for reading");
  std::ostringstream ss;
  ss << f.rdbuf();
  if (f.bad()) throw Error(path.string() + ": read error");
  return parse(ss.str(), path.string(), options);
}

bool Table::has(std::string_view name) const {
  for (const auto& n : names_) {
    if (n == name) return true;
  }
  return false;
}

const std::vector<double>& Table::column(std::string_view name) const {
  for (std::size_t i = 0; i < names_.size(); ++i) {
    if (names_[i] == name) return columns_[i];
  }
  std::string avail;
  for (const auto& n : names_) avail += (avail.empty() ? "" : ", ") + n;
  throw Error(source_ + ": no column '" + std::string(name) + "' (columns: " + avail + ")");
}

const std::vector<double>& Table::column(std::size_t index) const {
  if (index >= columns_.size()) {
    throw Error(source_ + ": column index " + std::to_string(index) + " out of range (" +
                   std::to_string(columns_.size()) + " columns)");
  }
  return columns_[index];
}

const std::vector<std::int64_t>& Table::integers(std::string_view name) const {
  const std::vector<double>& c = column(name);  // throws for a column the table lacks
  const auto i = static_cast<std::size_t>(&c - columns_.data());
  if (kinds_[i] != Kind::kInteger) {
    throw Error(source_ + ": column '" + std::string(name) +
                "' was not read as integers (expected it in Table::ReadOptions::integer_columns)");
  }
  return integers_[i];
}

const std::vector<std::string>& Table::texts(std::string_view name) const {
  const std::vector<double>& c = column(name);
  const auto i = static_cast<std::size_t>(&c - columns_.data());
  if (kinds_[i] != Kind::kText) {
    throw Error(source_ + ": column '" + std::string(name) +
                "' was not read as text (expected it in Table::ReadOptions::text_columns)");
  }
  return texts_[i];
}

}  // namespace pedalwave::csv
