#include "pedalwave/toolkit/table.hpp"

#include "pedalwave/toolkit/format.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <ostream>
#include <stdexcept>

namespace pedalwave::toolkit {

namespace {

std::size_t display_width(const std::string& s) {
  std::size_t n = 0;
  for (char c : s) n += ((static_cast<unsigned char>(c) & 0xC0) != 0x80) ? 1 : 0;
  return n;
}

bool is_number(const std::string& s) {
  if (s.empty()) return false;
  if (s == "nan" || s == "inf" || s == "-inf" || s == "-") return true;
  std::string_view v = s;
  if (v.front() == '+') v.remove_prefix(1);
  // a trailing '%' or 'x' (ratios) still reads as a number column
  if (!v.empty() && (v.back() == '%' || v.back() == 'x')) v.remove_suffix(1);
  double d = 0.0;
  const auto r = std::from_chars(v.data(), v.data() + v.size(), d);
  return r.ec == std::errc() && r.ptr == v.data() + v.size();
}

std::string pad(const std::string& s, std::size_t width, Align a) {
  const std::size_t w = display_width(s);
  if (w >= width) return s;
  const std::size_t gap = width - w;
  switch (a) {
    case Align::right: return std::string(gap, ' ') + s;
    case Align::center: return std::string(gap / 2, ' ') + s + std::string(gap - gap / 2, ' ');
    default: return s + std::string(gap, ' ');
  }
}

}  // namespace

Table::Table(std::vector<std::string> header, std::vector<Align> align)
    : header_(std::move(header)), align_(std::move(align)) {
  if (header_.empty()) throw std::invalid_argument("table: the header names no column");
  if (!align_.empty() && align_.size() != header_.size()) {
    throw std::invalid_argument("table: " + std::to_string(align_.size()) + " alignments for " +
                                std::to_string(header_.size()) + " columns");
  }
  if (align_.empty()) align_.assign(header_.size(), Align::automatic);
}

Table& Table::add_row(std::vector<std::string> cells) {
  if (cells.size() != header_.size()) {
    throw std::invalid_argument("table row " + std::to_string(rows_.size() + 1) + " has " +
                                std::to_string(cells.size()) + " cells but the header names " +
                                std::to_string(header_.size()) + " columns");
  }
  rows_.push_back(std::move(cells));
  return *this;
}

std::string Table::num(double v, int significant) { return toolkit::num(v, significant); }

Align Table::resolved(std::size_t col) const {
  if (align_[col] != Align::automatic) return align_[col];
  if (rows_.empty()) return Align::left;
  for (const auto& r : rows_) {
    if (!is_number(r[col])) return Align::left;
  }
  return Align::right;
}

std::string Table::to_text() const {
  const std::size_t n = header_.size();
  std::vector<std::size_t> w(n);
  for (std::size_t c = 0; c < n; ++c) {
    w[c] = display_width(header_[c]);
    for (const auto& r : rows_) w[c] = std::max(w[c], display_width(r[c]));
  }
  auto emit = [&](const std::vector<std::string>& cells, std::string& out) {
    std::string line;
    for (std::size_t c = 0; c < n; ++c) {
      if (c) line += "  ";
      line += pad(cells[c], w[c], resolved(c));
    }
    while (!line.empty() && line.back() == ' ') line.pop_back();
    out += line + '\n';
  };
  std::string out;
  emit(header_, out);
  std::string rule;
  for (std::size_t c = 0; c < n; ++c) {
    if (c) rule += "  ";
    rule += std::string(w[c], '-');
  }
  out += rule + '\n';
  for (const auto& r : rows_) emit(r, out);
  return out;
}

std::string Table::to_markdown() const {
  const std::size_t n = header_.size();
  auto cell = [](const std::string& s) {
    std::string o;
    for (char c : s) {
      if (c == '|') o += "\\|";
      else if (c == '\n') o += ' ';
      else o += c;
    }
    return o;
  };
  std::vector<std::size_t> w(n, 3);
  for (std::size_t c = 0; c < n; ++c) {
    w[c] = std::max(w[c], display_width(cell(header_[c])));
    for (const auto& r : rows_) w[c] = std::max(w[c], display_width(cell(r[c])));
  }
  std::string out = "|";
  for (std::size_t c = 0; c < n; ++c) out += " " + pad(cell(header_[c]), w[c], Align::left) + " |";
  out += "\n|";
  for (std::size_t c = 0; c < n; ++c) {
    const Align a = resolved(c);
    std::string dashes(w[c], '-');
    if (a == Align::right) dashes.back() = ':';
    if (a == Align::center) dashes.front() = dashes.back() = ':';
    out += " " + dashes + " |";
  }
  out += '\n';
  for (const auto& r : rows_) {
    out += "|";
    for (std::size_t c = 0; c < n; ++c) out += " " + pad(cell(r[c]), w[c], resolved(c)) + " |";
    out += '\n';
  }
  return out;
}

std::ostream& operator<<(std::ostream& os, const Table& t) { return os << t.to_text(); }

}  // namespace pedalwave::toolkit
