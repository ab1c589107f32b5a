// toolkit/report_template.hpp: {{name}} placeholders filled from the tool's values, the errors that
// name the template's file, line and placeholder, and the tables lined up through toolkit::Table.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "pedalwave/toolkit/report_template.hpp"
#include "pedalwave/toolkit/table.hpp"

namespace {

namespace tk = pedalwave::toolkit;
namespace fs = std::filesystem;

// The message of the TemplateError `f` throws ("" when it throws none).
template <class F>
std::string error_of(F&& f) {
  try {
    (void)f();
  } catch (const tk::TemplateError& e) {
    return e.what();
  }
  return "";
}

TEST(ReportTemplate, FillsEveryPlaceholderWithItsValue) {
  const std::map<std::string, std::string> v{{"a.speed", "2.18 cm/s"}, {"gain", "+13.7 %"}};
  EXPECT_EQ(tk::fill_template_text("speed {{a.speed}}, gain {{gain}}; again {{gain}}\n", "t.md.in", v),
            "speed 2.18 cm/s, gain +13.7 %; again +13.7 %\n");
  // Single braces and text around are left as they are.
  EXPECT_EQ(tk::fill_template_text("{x} {{gain}}}", "t", {{"gain", "1"}}), "{x} 1}");
}

TEST(ReportTemplate, AnUnknownPlaceholderNamesTheFileLineAndName) {
  const std::map<std::string, std::string> v{{"speed", "1"}};
  EXPECT_EQ(error_of([&] { return tk::fill_template_text("line one\n{{speed}}\nthird {{sped}} x\n", "r.md.in", v); }),
            "r.md.in:3: unknown placeholder {{sped}}: the tool gives no value of that name");
  EXPECT_EQ(error_of([&] { return tk::fill_template_text("a\nb {{speed\n}}", "r.md.in", v); }),
            "r.md.in:2: unterminated placeholder: '{{' without '}}'");
  EXPECT_EQ(error_of([&] { return tk::fill_template_text("{{speed}} {{two words}}", "r.md.in", v); }),
            "r.md.in:1: bad placeholder {{two words}}: expected a name of letters, digits, '_' and '.'");
}

TEST(ReportTemplate, AValueWithoutItsPlaceholderIsAnError) {
  // A template that dropped a number the tool computes says so instead of silently losing it.
  EXPECT_EQ(error_of([] { return tk::fill_template_text("{{a}}\n", "r.md.in", {{"a", "1"}, {"b", "2"}}); }),
            "r.md.in: the template has no placeholder {{b}} for the tool's value of that name");
}

TEST(ReportTemplate, ReadsTheFileAndNamesItInErrors) {
  const fs::path p = fs::temp_directory_path() / ("report_template_test_" + std::to_string(::getpid()) + ".md.in");
  {
    std::ofstream f(p);
    f << "# Report\n\nspeed {{speed}}\n{{missing}}\n";
  }
  EXPECT_EQ(error_of([&] { return tk::fill_template(p, {{"speed", "1"}}); }),
            p.string() + ":4: unknown placeholder {{missing}}: the tool gives no value of that name");
  EXPECT_EQ(tk::fill_template(p, {{"speed", "1"}, {"missing", "2"}}), "# Report\n\nspeed 1\n2\n");
  fs::remove(p);
  EXPECT_EQ(error_of([&] { return tk::fill_template(p, {}); }), "cannot read " + p.string());
}

TEST(ReportTemplate, TablesAreLinedUpAsTableWritesThem) {
  const std::string md =
      "intro\n\n| case | ours |\n| --- | --- |\n| flat | 2.18 cm/s |\n| stair, k_c = 10.1 | 12 |\n\n"
      "| a | b |\n|---|---|\n| x \\| y | 1 |\ntail\n";
  std::vector<std::size_t> rows;
  const std::string out = tk::align_markdown_tables(md, &rows);
  tk::Table t1({"case", "ours"});
  t1.add_row({"flat", "2.18 cm/s"}).add_row({"stair, k_c = 10.1", "12"});
  tk::Table t2({"a", "b"});
  t2.add_row({"x | y", "1"});
  EXPECT_EQ(out, "intro\n\n" + t1.to_markdown() + "\n" + t2.to_markdown() + "tail\n");
  EXPECT_EQ(rows, (std::vector<std::size_t>{2, 1}));
  // A single '|' line is not a table: left as it is.
  EXPECT_EQ(tk::align_markdown_tables("|x\n"), "|x\n");
}

}  // namespace
