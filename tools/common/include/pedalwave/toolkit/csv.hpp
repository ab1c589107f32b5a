// Numeric CSV for recordings and study results.
//
// Format: optional comment lines starting with '#', one header line naming every column, then
// rows of numbers separated by ','. Numbers are written as the shortest text that reads back to
// the same double (std::to_chars), so a write/read round trip is exact; NaN and ±Inf are written
// "nan", "inf", "-inf". Column names may not contain ',', '"', '#' at the start, or line breaks.
#pragma once

#include <cstddef>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace pedalwave::toolkit {

// Shortest round-trip text of a double ("0.1", "1e-300", "nan", "-inf").
[[nodiscard]] std::string format_double(double v);

// Errors of the CSV reader and writer; what() names the file (and line and column when known).
class CsvError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Streams rows to a file; nothing is kept in memory but the open stream.
class CsvWriter {
 public:
  // Creates (truncates) `path`, creating missing parent folders, and writes the header.
  // Throws CsvError naming the file when it cannot be opened, the header is empty, or a name is
  // empty, duplicated or contains a forbidden character (naming the column).
  CsvWriter(const std::filesystem::path& path, std::vector<std::string> header);

  // Writes "# text" (one comment line per line of text), e.g. the scene and the commit.
  void comment(std::string_view text);
  // Writes one row. Throws CsvError "<file>: row <k> has <m> values but the header names <n>
  // columns" when the count differs (nothing is written then).
  void row(std::span<const double> values);
  void row(std::initializer_list<double> values) { row(std::span<const double>(values.begin(), values.size())); }
  // A row with text columns too (e.g. a mode's name): a number is written as row() writes it, a
  // text quoted as RFC 4180 asks when it holds ',', '"' or a line break. The count is checked.
  struct Cell {
    Cell(double v) : number(v) {}                                  // NOLINT(google-explicit-constructor)
    Cell(std::string_view t) : text(t), is_text(true) {}           // NOLINT(google-explicit-constructor)
    Cell(const char* t) : Cell(std::string_view(t)) {}             // NOLINT(google-explicit-constructor)
    double number = 0.0;
    std::string_view text;
    bool is_text = false;
  };
  void row(std::span<const Cell> cells);

  void flush();
  // Flushes and closes; throws CsvError if a write failed. Called by the destructor (which
  // swallows errors); call it yourself to see them.
  void close();
  ~CsvWriter();
  CsvWriter(const CsvWriter&) = delete;
  CsvWriter& operator=(const CsvWriter&) = delete;

  [[nodiscard]] std::size_t columns() const { return header_.size(); }
  [[nodiscard]] std::size_t rows_written() const { return rows_; }
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
  std::vector<std::string> header_;
  std::ofstream out_;
  std::size_t rows_ = 0;
  std::string line_;  // reused row buffer
  void check_count(std::size_t n) const;
  void end_row();
};

// A numeric CSV held in memory, by column.
class CsvTable {
 public:
  // Reads a file. Throws CsvError naming the file (and the line and column) when it cannot be
  // opened, has no header, a header name repeats, a row has the wrong number of fields, or a
  // field is not a number.
  // How strict the reader is. The defaults suit the tools' own numeric files; a recording of
  // another program (pedalwave_monitor --record: text cells, a last line cut short while it was
  // written) is read with both on.
  struct ReadOptions {
    bool text_as_nan = false;  // a cell that is not a number reads as NaN instead of an error
    bool skip_ragged = false;  // a row with the wrong number of fields is skipped (and noted in
                               // skipped()) instead of an error
  };
  // Fields are separated by ',' and may be quoted ("a, b" is one field; "" inside is a quote).
  [[nodiscard]] static CsvTable read(const std::filesystem::path& path, ReadOptions options);
  [[nodiscard]] static CsvTable read(const std::filesystem::path& path) { return read(path, ReadOptions{}); }
  // Same from text; `source` names it in errors.
  [[nodiscard]] static CsvTable parse(std::string_view text, std::string source, ReadOptions options);
  [[nodiscard]] static CsvTable parse(std::string_view text, std::string source = "<text>") {
    return parse(text, std::move(source), ReadOptions{});
  }

  [[nodiscard]] const std::vector<std::string>& names() const { return names_; }
  [[nodiscard]] std::size_t rows() const { return columns_.empty() ? 0 : columns_.front().size(); }
  [[nodiscard]] std::size_t cols() const { return names_.size(); }
  [[nodiscard]] bool has(std::string_view name) const;
  // Column by name; throws CsvError naming the source, the column and the available names.
  [[nodiscard]] const std::vector<double>& column(std::string_view name) const;
  [[nodiscard]] const std::vector<double>& column(std::size_t index) const;
  // Comment lines (without the leading '#' and one following space), in order.
  [[nodiscard]] const std::vector<std::string>& comments() const { return comments_; }
  [[nodiscard]] const std::string& source() const { return source_; }
  // One line per row skipped by ReadOptions::skip_ragged ("<source>:<line>: row has 3 fields but
  // the header names 30 columns: skipped").
  [[nodiscard]] const std::vector<std::string>& skipped() const { return skipped_; }

 private:
  std::string source_;
  std::vector<std::string> names_;
  std::vector<std::vector<double>> columns_;
  std::vector<std::string> comments_;
  std::vector<std::string> skipped_;
};

}  // namespace pedalwave::toolkit
