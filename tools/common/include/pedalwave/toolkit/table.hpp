// Text tables for terminal output and for the README (Markdown).
//
//   Table t({"method", "dt [s]", "error [m]"});
//   t.add_row({"RK4", Table::num(1e-3), Table::num(2.5e-7)});
//   std::cout << t.to_text();      // aligned columns, a dashed rule under the header
//   std::cout << t.to_markdown();  // | method | dt [s] | error [m] | with alignment row
//
// Widths count Unicode code points (so "N·m" and "µs" align). Columns whose every cell is a
// number are right-aligned unless an alignment is given.
#pragma once

#include <cstddef>
#include <iosfwd>
#include <string>
#include <vector>

namespace pedalwave::toolkit {

enum class Align { automatic, left, right, center };

class Table {
 public:
  // Throws std::invalid_argument when the header is empty or `align` is non-empty with a
  // different size than the header.
  explicit Table(std::vector<std::string> header, std::vector<Align> align = {});

  // Throws std::invalid_argument "table row <k> has <m> cells but the header names <n>
  // columns" when the count differs.
  Table& add_row(std::vector<std::string> cells);

  // A number with `significant` digits (trailing zeros kept off, except in the exponent form),
  // exponent form outside [1e-3, 1e6): num(0.000123, 3) = "1.23e-04", num(0.000123) = "1.230e-04",
  // num(12.5) = "12.5", NaN = "nan" (toolkit::num, format.hpp).
  [[nodiscard]] static std::string num(double v, int significant = 4);

  [[nodiscard]] std::size_t rows() const { return rows_.size(); }
  [[nodiscard]] std::size_t cols() const { return header_.size(); }

  // Columns separated by two spaces, header underlined with '-'; every line ends with '\n'.
  [[nodiscard]] std::string to_text() const;
  // GitHub Markdown table; '|' in cells is escaped as "\|".
  [[nodiscard]] std::string to_markdown() const;

 private:
  [[nodiscard]] Align resolved(std::size_t col) const;
  std::vector<std::string> header_;
  std::vector<Align> align_;
  std::vector<std::vector<std::string>> rows_;
};

std::ostream& operator<<(std::ostream& os, const Table& t);  // to_text()

}  // namespace pedalwave::toolkit
