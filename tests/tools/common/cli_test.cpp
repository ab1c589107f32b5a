// The command-line policy every tool shares (toolkit/cli.hpp): a refused command line is one line
// on stderr and exit 2 (never CLI11's 104 … 114), --help exits 0, an unknown subcommand is named,
// and the validators refuse nan, inf and out-of-range numbers.
#include <gtest/gtest.h>

#include <algorithm>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "pedalwave/toolkit/cli.hpp"

namespace cli = pedalwave::toolkit::cli;

namespace {
struct Outcome {
  std::optional<int> rc;
  std::string err;
};
// Parses `args` with a small app of two subcommands, capturing stderr.
Outcome parse(std::vector<std::string> args, bool subcommands) {
  CLI::App app{"test"};
  double x = 1.0;
  if (subcommands) {
    app.require_subcommand(1);
    app.add_subcommand("flat", "")->add_option("--x", x)->check(cli::finite_positive());
    app.add_subcommand("stair", "");
  } else {
    app.add_option("--x", x)->check(cli::finite_in(-1, 1));
  }
  args.insert(args.begin(), "tool");
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  std::ostringstream err;
  std::streambuf* old = std::cerr.rdbuf(err.rdbuf());
  std::ostringstream out;
  std::streambuf* old_out = std::cout.rdbuf(out.rdbuf());
  Outcome o{cli::parse(app, static_cast<int>(argv.size()), argv.data(), "tool"), ""};
  std::cerr.rdbuf(old);
  std::cout.rdbuf(old_out);
  o.err = err.str();
  return o;
}
int lines(const std::string& s) { return static_cast<int>(std::count(s.begin(), s.end(), '\n')); }
}  // namespace

TEST(CliPolicy, ErrorsAreOneLineAndExit2) {
  for (const std::vector<std::string>& a : std::vector<std::vector<std::string>>{
           {"--nope"}, {"--x"}, {"--x", "abc"}, {"--x", "nan"}, {"--x", "inf"}, {"--x", "2"}}) {
    const Outcome o = parse(a, false);
    ASSERT_TRUE(o.rc.has_value()) << a[0];
    EXPECT_EQ(*o.rc, cli::kExitBadInput) << a[0];
    EXPECT_EQ(o.err.rfind("tool: error: ", 0), 0u) << o.err;
    EXPECT_EQ(lines(o.err), 1) << o.err;
  }
  EXPECT_NE(parse({"--x", "nan"}, false).err.find("'nan': expected a finite number in [-1, 1]"), std::string::npos);
  EXPECT_FALSE(parse({"--x", "0.5"}, false).rc.has_value()) << "a good command line goes on";
  EXPECT_EQ(parse({"--help"}, false).rc, 0);
}

TEST(CliPolicy, AnUnknownSubcommandIsNamed) {
  Outcome o = parse({"dance"}, true);
  EXPECT_EQ(o.rc, cli::kExitBadInput);
  EXPECT_EQ(o.err, "tool: error: 'dance' is not a subcommand: expected one of flat, stair (see --help)\n");
  o = parse({"flat", "--x", "-1"}, true);
  EXPECT_EQ(o.rc, cli::kExitBadInput);
  EXPECT_NE(o.err.find("'-1': expected a finite number > 0"), std::string::npos) << o.err;
  EXPECT_FALSE(parse({"flat", "--x", "3"}, true).rc.has_value());
}
