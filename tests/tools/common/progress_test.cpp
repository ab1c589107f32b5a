// Progress bar (tools/common/src/progress.cpp): a line per 10 % in logs, each once and in order
// even with many threads; in-place redraws on a terminal; a final total line.
#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "pedalwave/toolkit/progress.hpp"

namespace tk = pedalwave::toolkit;

namespace {

std::vector<std::string> lines_of(const std::string& s) {
  std::vector<std::string> out;
  std::istringstream in(s);
  for (std::string l; std::getline(in, l);) out.push_back(l);
  return out;
}

}  // namespace

TEST(Progress, LinesStylePrintsEachTenPercentOnce) {
  std::ostringstream os;
  {
    tk::Progress p("sweep", 1000, {.style = tk::Progress::Style::lines, .out = &os});
    for (int i = 0; i < 1000; ++i) p.advance();
    EXPECT_EQ(p.done(), 1000u);
    p.finish();
  }
  const auto lines = lines_of(os.str());
  ASSERT_EQ(lines.size(), 11u) << os.str();
  for (int k = 1; k <= 10; ++k) {
    EXPECT_EQ(lines[k - 1].rfind("sweep: " + std::to_string(10 * k) + "% (" + std::to_string(100 * k) + "/1000", 0), 0u)
        << lines[k - 1];
  }
  EXPECT_NE(lines[0].find("ETA"), std::string::npos);
  EXPECT_NE(lines[10].find("sweep: 1000/1000 done in"), std::string::npos) << lines[10];
}

TEST(Progress, ThreadsAdvanceTogetherAndStepsStayOrdered) {
  std::ostringstream os;
  tk::Progress p("mt", 40000, {.style = tk::Progress::Style::lines, .out = &os});
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&p] {
      for (int i = 0; i < 10000; ++i) p.advance();
    });
  }
  for (auto& t : threads) t.join();
  p.finish();
  EXPECT_EQ(p.done(), 40000u);
  const auto lines = lines_of(os.str());
  ASSERT_EQ(lines.size(), 11u) << os.str();
  for (int k = 1; k <= 10; ++k) {
    EXPECT_EQ(lines[k - 1].rfind("mt: " + std::to_string(10 * k) + "%", 0), 0u) << lines[k - 1];
  }
}

TEST(Progress, BigStepsReportTheHighestStepReached) {
  std::ostringstream os;
  tk::Progress p("jump", 10, {.style = tk::Progress::Style::lines, .out = &os});
  p.advance(5);  // 50 %
  p.advance(5);  // 100 %
  p.finish();
  const auto lines = lines_of(os.str());
  ASSERT_EQ(lines.size(), 3u) << os.str();
  EXPECT_EQ(lines[0].rfind("jump: 50%", 0), 0u);
  EXPECT_EQ(lines[1].rfind("jump: 100%", 0), 0u);
}

TEST(Progress, TtyStyleRedrawsInPlace) {
  std::ostringstream os;
  {
    tk::Progress p("run", 50, {.style = tk::Progress::Style::tty, .out = &os, .redraw_interval_s = 0.0, .bar_width = 10});
    for (int i = 0; i < 50; ++i) p.advance();
  }  // destructor finishes
  const std::string s = os.str();
  EXPECT_NE(s.find("\rrun ["), std::string::npos);
  EXPECT_NE(s.find("[##########] 100% 50/50"), std::string::npos) << s;
  EXPECT_NE(s.find("run: 50/50 done in"), std::string::npos) << s;
  EXPECT_EQ(s.back(), '\n');
  // only the final two lines end with a newline: everything before redraws in place
  EXPECT_EQ(lines_of(s).size(), 2u);
}

TEST(Progress, FinishIsIdempotentAndSilentPrintsNothing) {
  std::ostringstream os;
  {
    tk::Progress p("once", 4, {.style = tk::Progress::Style::lines, .out = &os});
    p.advance(4);
    p.finish();
    p.finish();
    p.advance();  // after finish: counted, not printed
    EXPECT_EQ(p.done(), 5u);
  }
  EXPECT_EQ(lines_of(os.str()).size(), 2u) << os.str();
  std::ostringstream quiet;
  {
    tk::Progress p("q", 10, {.style = tk::Progress::Style::silent, .out = &quiet});
    p.advance(10);
  }
  EXPECT_TRUE(quiet.str().empty());
}

TEST(Progress, UnknownTotalCountsOnly) {
  std::ostringstream os;
  tk::Progress p("open-ended", 0, {.style = tk::Progress::Style::lines, .out = &os});
  p.advance(7);
  p.finish();
  const auto lines = lines_of(os.str());
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_NE(lines[0].find("open-ended: 7 done in"), std::string::npos) << lines[0];
}

TEST(Progress, AutomaticStyleOnANonTerminalStreamUsesLines) {
  std::ostringstream os;
  tk::Progress p("auto", 10, {.out = &os});
  p.advance(10);
  p.finish();
  EXPECT_EQ(os.str().find('\r'), std::string::npos);
  EXPECT_EQ(lines_of(os.str()).size(), 2u);
}

TEST(Progress, FormatsDurationsForPeople) {
  EXPECT_EQ(pedalwave::toolkit::format_duration(0.35), "350 ms");
  EXPECT_EQ(pedalwave::toolkit::format_duration(12.34), "12.3 s");
  EXPECT_EQ(pedalwave::toolkit::format_duration(125.0), "2 min 05 s");
  EXPECT_EQ(pedalwave::toolkit::format_duration(3720.0), "1 h 02 min");
}
