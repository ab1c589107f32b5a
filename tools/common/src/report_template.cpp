#include "pedalwave/toolkit/report_template.hpp"

#include <fstream>
#include <set>
#include <sstream>

#include "pedalwave/toolkit/table.hpp"

namespace pedalwave::toolkit {

namespace {

bool name_char(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '.';
}

// Cells of a Markdown table line "| a | b |" (unescaping "\|"), trimmed.
std::vector<std::string> cells_of(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  bool open = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (c == '\\' && i + 1 < line.size() && line[i + 1] == '|') {
      cur += '|';
      ++i;
    } else if (c == '|') {
      if (open) out.push_back(cur);
      cur.clear();
      open = true;
    } else {
      cur += c;
    }
  }
  for (std::string& s : out) {
    s.erase(0, s.find_first_not_of(' '));
    const auto last = s.find_last_not_of(' ');
    s.erase(last == std::string::npos ? 0 : last + 1);
  }
  return out;
}

}  // namespace

std::string fill_template_text(const std::string& text, const std::string& origin,
                               const std::map<std::string, std::string>& values) {
  std::string out;
  out.reserve(text.size());
  std::set<std::string> used;
  std::size_t line = 1, i = 0;
  while (i < text.size()) {
    if (text.compare(i, 2, "{{") != 0) {
      if (text[i] == '\n') ++line;
      out += text[i++];
      continue;
    }
    const std::size_t end = text.find("}}", i + 2);
    const std::size_t nl = text.find('\n', i);
    if (end == std::string::npos || (nl != std::string::npos && nl < end))
      throw TemplateError(origin + ":" + std::to_string(line) + ": unterminated placeholder: '{{' without '}}'");
    const std::string name = text.substr(i + 2, end - i - 2);
    bool ok = !name.empty();
    for (char c : name) ok = ok && name_char(c);
    if (!ok)
      throw TemplateError(origin + ":" + std::to_string(line) + ": bad placeholder {{" + name +
                          "}}: expected a name of letters, digits, '_' and '.'");
    const auto v = values.find(name);
    if (v == values.end())
      throw TemplateError(origin + ":" + std::to_string(line) + ": unknown placeholder {{" + name +
                          "}}: the tool gives no value of that name");
    used.insert(name);
    out += v->second;
    i = end + 2;
  }
  for (const auto& [name, value] : values)
    if (!used.count(name))
      throw TemplateError(origin + ": the template has no placeholder {{" + name + "}} for the tool's value of that name");
  return out;
}

std::string fill_template(const std::filesystem::path& file, const std::map<std::string, std::string>& values) {
  std::ifstream f(file, std::ios::binary);
  if (!f) throw TemplateError("cannot read " + file.string());
  std::ostringstream os;
  os << f.rdbuf();
  return fill_template_text(os.str(), file.string(), values);
}

std::string align_markdown_tables(const std::string& md, std::vector<std::size_t>* rows_per_table) {
  std::vector<std::string> lines;
  {
    std::size_t a = 0;
    while (a < md.size()) {
      const std::size_t b = md.find('\n', a);
      if (b == std::string::npos) {
        lines.push_back(md.substr(a));
        break;
      }
      lines.push_back(md.substr(a, b - a + 1));
      a = b + 1;
    }
  }
  auto is_row = [](const std::string& l) { return !l.empty() && l[0] == '|'; };
  std::string out;
  for (std::size_t i = 0; i < lines.size();) {
    if (!is_row(lines[i])) {
      out += lines[i++];
      continue;
    }
    std::size_t j = i;
    while (j < lines.size() && is_row(lines[j])) ++j;
    // A table: header, alignment row, then the rows (anything shorter is left as it is).
    if (j - i < 2) {
      out += lines[i++];
      continue;
    }
    Table t(cells_of(lines[i]));
    for (std::size_t k = i + 2; k < j; ++k) t.add_row(cells_of(lines[k]));
    if (rows_per_table) rows_per_table->push_back(t.rows());
    std::string text = t.to_markdown();
    if (lines[j - 1].back() != '\n' && !text.empty() && text.back() == '\n') text.pop_back();
    out += text;
    i = j;
  }
  return out;
}

}  // namespace pedalwave::toolkit
