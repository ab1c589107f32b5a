// The project's one CSV writer and reader (pedalwave::csv).
//
// Format: optional comment lines starting with '#', one header line naming every column, then
// rows separated by ','. Numbers are written as the shortest text that reads back to the same
// double, so a write/read round trip is exact; a text cell is quoted as RFC 4180 asks ("" inside
// is a quote). Column names may not contain ',', '"', a line break, or a leading '#'.
//
// Two spellings of a number, both shortest round-trip digits (Writer::Options::numbers):
//   kShortest  the shorter of fixed and exponent form (std::to_chars): 100000 → "1e+05",
//              0.0001 → "1e-04"; NaN and ±Inf "nan", "inf", "-inf" (the tools' data files)
//   kFixed     fixed form from 1e-4 up to 1e16, exponent form outside, as fmt's "{}" writes a
//              double: 100000 → "100000", 0.0001 → "0.0001", 5e-5 → "5e-05"; a NaN keeps its
//              sign ("-nan") (the telemetry recorder's files, read by pedalwave_plotrec,
//              pedalwave_identify and the monitor)
#pragma once

#include <concepts>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

namespace pedalwave::csv {

// Errors of the reader and writer; what() names the file (and line and column when known).
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class Numbers { kShortest, kFixed };

// Appends the text of `v` in the given spelling (see above).
void append_number(std::string& out, double v, Numbers numbers = Numbers::kShortest);

// Streams rows to a file; nothing is kept in memory but the open stream and one line buffer.
class Writer {
 public:
  struct Options {
    Numbers numbers = Numbers::kShortest;
    bool create_folders = true;  // create missing parent folders of the path
  };

  // Creates (truncates) `path` and writes the header. Throws Error naming the file when it
  // cannot be opened (with the system's reason), the header is empty, or a name is empty,
  // duplicated or contains a forbidden character (naming the column).
  Writer(const std::filesystem::path& path, std::vector<std::string> header, Options options);
  Writer(const std::filesystem::path& path, std::vector<std::string> header)
      : Writer(path, std::move(header), Options{}) {}
  // Creates (truncates) `path` now and leaves the header to header(): for a file whose columns
  // are known only from its first record (the recorder's per-joint columns). Throws as above.
  [[nodiscard]] static Writer header_later(const std::filesystem::path& path, Options options);

  // Writes the header line (once, before any row or comment); checked as the constructor checks.
  void header(std::vector<std::string> names);
  [[nodiscard]] bool has_header() const { return !header_.empty(); }

  // Writes "# text" (one comment line per line of text), e.g. the scene and the commit.
  void comment(std::string_view text);

  // A whole row of numbers. Throws Error "<file>: row <k> has <m> values but the header names
  // <n> columns" when the count differs (nothing is written then).
  void row(std::span<const double> values);
  void row(std::initializer_list<double> values) {
    row(std::span<const double>(values.begin(), values.size()));
  }
  // A row with text columns too (e.g. a mode's name): a number is written as row() writes it, a
  // text quoted only when it holds ',', '"' or a line break. The count is checked.
  struct Cell {
    Cell(double v) : number(v) {}                                  // NOLINT(google-explicit-constructor)
    Cell(std::string_view t) : text(t), is_text(true) {}           // NOLINT(google-explicit-constructor)
    Cell(const char* t) : Cell(std::string_view(t)) {}             // NOLINT(google-explicit-constructor)
    double number = 0.0;
    std::string_view text;
    bool is_text = false;
  };
  void row(std::span<const Cell> cells);

  // A row cell by cell, into the reused line buffer: number/integer/text/quoted/empty, then
  // end_row(), which checks the count (the row is dropped and Error thrown when it differs).
  Writer& number(double v);
  template <std::integral T>
    requires(!std::same_as<T, bool> && !std::same_as<T, char>)
  Writer& integer(T v) {
    if constexpr (std::is_signed_v<T>) return append_integer(static_cast<long long>(v));
    else return append_unsigned(static_cast<unsigned long long>(v));
  }
  Writer& text(std::string_view t);    // quoted only when needed
  Writer& quoted(std::string_view t);  // always quoted ("" escapes ")
  Writer& empty();                     // an empty cell (a missing value)
  void end_row();

  void flush();
  // Flushes and closes; throws Error if a write failed. Called by the destructor (which
  // swallows errors); call it yourself to see them.
  void close();
  ~Writer();
  Writer(Writer&&) = default;
  Writer& operator=(Writer&&) = default;
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  [[nodiscard]] std::size_t columns() const { return header_.size(); }
  [[nodiscard]] std::size_t rows_written() const { return rows_; }
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
  Options options_;
  std::vector<std::string> header_;
  std::ofstream out_;
  std::size_t rows_ = 0;
  std::size_t cells_ = 0;  // cells in line_ so far
  std::string line_;       // reused row buffer
  struct Late {};
  Writer(const std::filesystem::path& path, Options options, Late);  // header_later
  void open();
  void begin_cell();
  Writer& append_integer(long long v);
  Writer& append_unsigned(unsigned long long v);
  void check_count(std::size_t n);
};

// A numeric CSV held in memory, by column (and columns asked for as exact integers or as text).
class Table {
 public:
  // How strict the reader is. The defaults suit the tools' own numeric files; a recording of
  // another program (pedalwave_monitor --record: text cells, a last line cut short while it was
  // written) is read with both on.
  struct ReadOptions {
    bool text_as_nan = false;  // a cell that is not a number reads as NaN instead of an error
    bool skip_ragged = false;  // a row with the wrong number of fields is skipped (and noted in
                               // skipped()) instead of an error
    // Columns read exactly as signed 64-bit integers too (integers()): a double holds every
    // integer only up to 2^53, a nanosecond stamp is beyond. A cell that is not an integer in
    // [-2^63, 2^63) is an error naming the file, line and column (text_as_nan does not apply);
    // column() holds the nearest double. A name the header lacks is an error.
    std::vector<std::string> integer_columns = {};
    // Columns of text (a name, a mode's name): kept as read (texts()), not parsed as numbers
    // (column() holds NaN). A name the header lacks is ignored.
    std::vector<std::string> text_columns = {};
  };
  // Reads a file. Throws Error naming the file (and the line and column) when it cannot be
  // opened, has no header, a header name repeats, a row has the wrong number of fields, or a
  // field is not a number. Fields are separated by ',' and may be quoted ("a, b" is one field;
  // "" inside is a quote).
  [[nodiscard]] static Table read(const std::filesystem::path& path, ReadOptions options);
  [[nodiscard]] static Table read(const std::filesystem::path& path) { return read(path, ReadOptions{}); }
  // Same from text; `source` names it in errors.
  [[nodiscard]] static Table parse(std::string_view text, std::string source, ReadOptions options);
  [[nodiscard]] static Table parse(std::string_view text, std::string source = "<text>") {
    return parse(text, std::move(source), ReadOptions{});
  }

  [[nodiscard]] const std::vector<std::string>& names() const { return names_; }
  [[nodiscard]] std::size_t rows() const { return columns_.empty() ? 0 : columns_.front().size(); }
  [[nodiscard]] std::size_t cols() const { return names_.size(); }
  [[nodiscard]] bool has(std::string_view name) const;
  // Column by name; throws Error naming the source, the column and the available names.
  [[nodiscard]] const std::vector<double>& column(std::string_view name) const;
  [[nodiscard]] const std::vector<double>& column(std::size_t index) const;
  // A column read as integers (ReadOptions::integer_columns) / as text (text_columns); throws
  // Error naming the source and the column when it is not one.
  [[nodiscard]] const std::vector<std::int64_t>& integers(std::string_view name) const;
  [[nodiscard]] const std::vector<std::string>& texts(std::string_view name) const;
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
  enum class Kind : std::uint8_t { kNumber, kInteger, kText };
  std::vector<Kind> kinds_;                          // per column
  std::vector<std::vector<std::int64_t>> integers_;  // per column (kInteger ones filled)
  std::vector<std::vector<std::string>> texts_;      // per column (kText ones filled)
  std::vector<std::string> comments_;
  std::vector<std::string> skipped_;
};

}  // namespace pedalwave::csv
