#include "pedalwave/toolkit/csv.hpp"

#include "pedalwave/toolkit/format.hpp"

#include <charconv>
#include <cstdlib>
#include <cmath>
#include <deque>
#include <limits>
#include <set>
#include <sstream>
#include <system_error>

namespace pedalwave::toolkit {

std::string format_double(double v) { return exact(v); }

// ---- writer ------------------------------------------------------------------------------------

CsvWriter::CsvWriter(const std::filesystem::path& path, std::vector<std::string> header)
    : path_(path), header_(std::move(header)) {
  const std::string where = "CSV '" + path_.string() + "'";
  if (header_.empty()) throw CsvError(where + ": the header names no column");
  std::set<std::string_view> seen;
  for (std::size_t i = 0; i < header_.size(); ++i) {
    const std::string& n = header_[i];
    const std::string col = "column " + std::to_string(i + 1) + " ('" + n + "')";
    if (n.empty()) throw CsvError(where + ": column " + std::to_string(i + 1) + " has an empty name");
    if (n.find_first_of(",\"\r\n") != std::string::npos || (i == 0 && n[0] == '#')) {
      throw CsvError(where + ": " + col + " contains ',', '\"', a line break or a leading '#'");
    }
    if (!seen.insert(n).second) throw CsvError(where + ": " + col + " is named twice");
  }
  std::error_code ec;
  if (path_.has_parent_path()) std::filesystem::create_directories(path_.parent_path(), ec);
  out_.open(path_, std::ios::binary | std::ios::trunc);
  if (!out_) throw CsvError(where + ": cannot open for writing");
  std::string h;
  for (std::size_t i = 0; i < header_.size(); ++i) {
    if (i) h += ',';
    h += header_[i];
  }
  h += '\n';
  out_.write(h.data(), static_cast<std::streamsize>(h.size()));
}

void CsvWriter::comment(std::string_view text) {
  std::size_t start = 0;
  while (true) {
    const std::size_t nl = text.find('\n', start);
    const std::string_view line = text.substr(start, nl == std::string_view::npos ? std::string_view::npos : nl - start);
    out_ << "# " << line << '\n';
    if (nl == std::string_view::npos) break;
    start = nl + 1;
  }
}

namespace {
void append_number(std::string& line, double v) {
  char buf[32];
  if (std::isnan(v)) {
    line += "nan";
  } else if (std::isinf(v)) {
    line += v > 0 ? "inf" : "-inf";
  } else {
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    line.append(buf, r.ptr);
  }
}
void append_text(std::string& line, std::string_view t) {
  if (t.find_first_of(",\"\r\n") == std::string_view::npos) {
    line += t;
    return;
  }
  line += '"';
  for (const char c : t) {
    if (c == '"') line += '"';
    line += c;
  }
  line += '"';
}
}  // namespace

void CsvWriter::check_count(std::size_t n) const {
  if (n != header_.size()) {
    throw CsvError("CSV '" + path_.string() + "': row " + std::to_string(rows_ + 1) + " has " +
                   std::to_string(n) + " values but the header names " + std::to_string(header_.size()) +
                   " columns");
  }
}

void CsvWriter::end_row() {
  line_ += '\n';
  out_.write(line_.data(), static_cast<std::streamsize>(line_.size()));
  ++rows_;
}

void CsvWriter::row(std::span<const double> values) {
  check_count(values.size());
  line_.clear();
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (i) line_ += ',';
    append_number(line_, values[i]);
  }
  end_row();
}

void CsvWriter::row(std::span<const Cell> cells) {
  check_count(cells.size());
  line_.clear();
  for (std::size_t i = 0; i < cells.size(); ++i) {
    if (i) line_ += ',';
    if (cells[i].is_text) append_text(line_, cells[i].text);
    else append_number(line_, cells[i].number);
  }
  end_row();
}

void CsvWriter::flush() { out_.flush(); }

void CsvWriter::close() {
  if (!out_.is_open()) return;
  out_.flush();
  const bool ok = static_cast<bool>(out_);
  out_.close();
  if (!ok) throw CsvError("CSV '" + path_.string() + "': write failed (disk full or file removed?)");
}

CsvWriter::~CsvWriter() {
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

CsvTable CsvTable::parse(std::string_view text, std::string source, ReadOptions options) {
  CsvTable t;
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
        if (n.empty()) throw CsvError(where + ": header column " + std::to_string(i + 1) + " has an empty name");
        if (!seen.insert(n).second) {
          throw CsvError(where + ": header column " + std::to_string(i + 1) + " ('" + std::string(n) + "') is named twice");
        }
        t.names_.emplace_back(n);
      }
      t.columns_.resize(t.names_.size());
      have_header = true;
      continue;
    }
    if (fields.size() != t.names_.size()) {
      const std::string what = where + ": row has " + std::to_string(fields.size()) +
                               " fields but the header names " + std::to_string(t.names_.size()) + " columns";
      if (!options.skip_ragged) throw CsvError(what);
      t.skipped_.push_back(what + ": skipped");
      continue;
    }
    for (std::size_t i = 0; i < fields.size(); ++i) {
      double v = 0.0;
      if (!parse_number(fields[i], v)) {
        if (options.text_as_nan) {
          t.columns_[i].push_back(std::numeric_limits<double>::quiet_NaN());
          continue;
        }
        throw CsvError(where + ": column " + std::to_string(i + 1) + " ('" + t.names_[i] + "'): '" +
                       std::string(fields[i]) + "' is not a number");
      }
      t.columns_[i].push_back(v);
    }
  }
  if (!have_header) throw CsvError(t.source_ + ": no header line (expected the column names)");
  return t;
}

CsvTable CsvTable::read(const std::filesystem::path& path, ReadOptions options) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw CsvError(path.string() + ": cannot open for reading");
  std::ostringstream ss;
  ss << f.rdbuf();
  if (f.bad()) throw CsvError(path.string() + ": read error");
  return parse(ss.str(), path.string(), options);
}

bool CsvTable::has(std::string_view name) const {
  for (const auto& n : names_) {
    if (n == name) return true;
  }
  return false;
}

const std::vector<double>& CsvTable::column(std::string_view name) const {
  for (std::size_t i = 0; i < names_.size(); ++i) {
    if (names_[i] == name) return columns_[i];
  }
  std::string avail;
  for (const auto& n : names_) avail += (avail.empty() ? "" : ", ") + n;
  throw CsvError(source_ + ": no column '" + std::string(name) + "' (columns: " + avail + ")");
}

const std::vector<double>& CsvTable::column(std::size_t index) const {
  if (index >= columns_.size()) {
    throw CsvError(source_ + ": column index " + std::to_string(index) + " out of range (" +
                   std::to_string(columns_.size()) + " columns)");
  }
  return columns_[index];
}

}  // namespace pedalwave::toolkit
