// A report from a template file: the prose and layout in a Markdown file a person edits, the
// numbers filled in by the tool that computed them.
//
//   {{name}}  is replaced by values.at("name") (names: letters, digits, '_', '.');
//   a table   (consecutive lines starting with '|': header, alignment row, rows) is written again
//             through toolkit::Table, so the template's rows need no padding and the columns line
//             up whatever the numbers' widths.
//
// Every placeholder must have a value and every value a placeholder: a template that names an
// unknown value, or drops one the tool gives, is an error naming the file, line and placeholder.
#pragma once

#include <cstddef>
#include <filesystem>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace pedalwave::toolkit {

class TemplateError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Fills `text` (read from `origin`, for the messages). Throws TemplateError
//   "<origin>:<line>: unknown placeholder {{x}}: the tool gives no value of that name"
//   "<origin>:<line>: unterminated placeholder: '{{' without '}}'"
//   "<origin>:<line>: bad placeholder {{…}}: expected a name of letters, digits, '_' and '.'"
//   "<origin>: the template has no placeholder {{x}} for the tool's value of that name"
[[nodiscard]] std::string fill_template_text(const std::string& text, const std::string& origin,
                                             const std::map<std::string, std::string>& values);
// Reads `file` (TemplateError "cannot read <file>") and fills it.
[[nodiscard]] std::string fill_template(const std::filesystem::path& file,
                                        const std::map<std::string, std::string>& values);

// Rewrites every Markdown table of `md` through Table::to_markdown (automatic alignment);
// rows_per_table, when given, receives each table's number of body rows in order.
[[nodiscard]] std::string align_markdown_tables(const std::string& md,
                                                std::vector<std::size_t>* rows_per_table = nullptr);

}  // namespace pedalwave::toolkit
