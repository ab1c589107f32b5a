// pedalwave::campaign: exact records, chunking, the campaign folder's bookkeeping, the local
// backend, and the Slurm backend's loop (submission, following, resubmission, resume) against
// stand-in sbatch/squeue scripts that run the array tasks at once through a stand-in tool
// (fake_worker.cpp). The real cluster: run_slurm_tests.sh (label slurm).
#include <gtest/gtest.h>

#include <unistd.h>

#include <atomic>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "pedalwave/campaign/campaign.hpp"
#include "pedalwave/config/yaml_reader.hpp"

namespace campaign = pedalwave::campaign;
namespace fs = std::filesystem;

namespace {

// The stand-in tool's runner (fake_worker.cpp), to check what the workers wrote.
std::string fake(const std::string& spec) {
  campaign::Record r;
  r.put_text("hash", campaign::hash(spec)).put_int("length", static_cast<long long>(spec.size()));
  return r.line();
}

std::string slurp(const fs::path& p) {
  std::ifstream f(p);
  std::ostringstream os;
  os << f.rdbuf();
  return os.str();
}
void write(const fs::path& p, const std::string& text) {
  std::ofstream f(p);
  f << text;
}
int count_lines(const std::string& text, const std::string& prefix) {
  std::istringstream is(text);
  int n = 0;
  for (std::string l; std::getline(is, l);) n += l.rfind(prefix, 0) == 0;
  return n;
}

class TempDir : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("pw_campaign_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

}  // namespace

// ---- records ---------------------------------------------------------------------------------------
TEST(CampaignRecord, DoublesTextAndIntegersComeBackBitForBit) {
  const std::vector<double> xs{0.1, -0.0, 0.0, 1.0 / 3.0, 6.02214076e23, std::numeric_limits<double>::denorm_min(),
                               std::numeric_limits<double>::max(), -std::numeric_limits<double>::infinity(),
                               std::numeric_limits<double>::infinity(), 0.013970298729066561};
  campaign::Record r;
  for (std::size_t i = 0; i < xs.size(); ++i) r.put("x" + std::to_string(i), xs[i]);
  r.put("nan", std::nan("")).put_int("big", -9007199254740993LL);
  const std::string text = "a\tb\nc\r%09 %25 %\n, ünïcode=ok";
  r.put_text("text", text).put_text("empty", "");
  const std::string line = r.line();
  EXPECT_EQ(line.find('\n'), std::string::npos);
  const campaign::Record back = campaign::Record::parse(line, "test");
  for (std::size_t i = 0; i < xs.size(); ++i)
    EXPECT_EQ(std::bit_cast<std::uint64_t>(back.number("x" + std::to_string(i))), std::bit_cast<std::uint64_t>(xs[i]))
        << "x" << i << " = " << campaign::hex(xs[i]);
  EXPECT_TRUE(std::isnan(back.number("nan")));
  EXPECT_EQ(back.integer("big"), -9007199254740993LL);
  EXPECT_EQ(back.text("text"), text);
  EXPECT_EQ(back.text("empty"), "");
  EXPECT_TRUE(back.has("empty"));
  EXPECT_FALSE(back.has("absent"));
}

TEST(CampaignRecord, ErrorsNameTheRecordTheKeyAndTheValue) {
  const campaign::Record r = campaign::Record::parse("a=0x1p+0\tb=zwei\tc=%0Q", "specs.txt:3");
  try {
    (void)r.number("b");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("specs.txt:3: b = 'zwei': expected a number"), std::string::npos) << e.what();
  }
  try {
    (void)r.number("d");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("specs.txt:3: d: expected the key"), std::string::npos) << e.what();
  }
  EXPECT_THROW((void)r.integer("a"), std::invalid_argument);
  EXPECT_THROW((void)r.text("c"), std::invalid_argument);
  EXPECT_THROW((void)campaign::Record::parse("novalue", "x"), std::invalid_argument);
  EXPECT_THROW((void)campaign::Record::parse("=v", "x"), std::invalid_argument);
}

TEST(CampaignRecord, HashIsFnv1aAndTellsTextsApart) {
  EXPECT_EQ(campaign::hash(""), "cbf29ce484222325");  // FNV-1a 64 offset basis
  EXPECT_EQ(campaign::hash("a"), "af63dc4c8601ec8c");  // FNV-1a 64 of "a"
  EXPECT_NE(campaign::hash("k_c=0x1p+0"), campaign::hash("k_c=0x1p+1"));
}

// ---- chunking --------------------------------------------------------------------------------------
TEST(CampaignChunks, TasksCoverEveryRunOnceInOrder) {
  for (std::size_t n : {0u, 1u, 7u, 9u, 10u, 151u})
    for (int chunk : {1, 2, 3, 10, 200}) {
      const std::size_t tasks = campaign::task_count(n, chunk);
      EXPECT_EQ(tasks, (n + static_cast<std::size_t>(chunk) - 1) / static_cast<std::size_t>(chunk));
      std::size_t next = 0;
      for (std::size_t t = 0; t < tasks; ++t) {
        const auto [a, b] = campaign::task_runs(t, n, chunk);
        EXPECT_EQ(a, next);
        EXPECT_GT(b, a);
        EXPECT_LE(b - a, static_cast<std::size_t>(chunk));
        next = b;
      }
      EXPECT_EQ(next, n) << n << " runs, chunk " << chunk;
      const auto [a, b] = campaign::task_runs(tasks, n, chunk);  // past the end: empty
      EXPECT_EQ(a, b);
    }
}

TEST(CampaignChunks, ArrayRangesAreSbatchSyntax) {
  EXPECT_EQ(campaign::array_ranges({0, 1, 2, 5, 7, 8}), "0-2,5,7-8");
  EXPECT_EQ(campaign::array_ranges({3}), "3");
  EXPECT_EQ(campaign::array_ranges({}), "");
}

// ---- the campaign folder -----------------------------------------------------------------------------
TEST_F(TempDir, ResultFilesAreKeptOnlyForTheirSpecification) {
  fs::create_directories(dir_ / "results");
  campaign::write_result(dir_, 4, "spec four", "v=0x1p-3");
  std::string r;
  EXPECT_TRUE(campaign::read_result(dir_, 4, "spec four", r));
  EXPECT_EQ(r, "v=0x1p-3");
  EXPECT_FALSE(campaign::read_result(dir_, 4, "spec 4", r));   // another campaign's run 4
  EXPECT_FALSE(campaign::read_result(dir_, 5, "spec four", r));  // never written
  const std::string whole = slurp(campaign::result_file(dir_, 4));
  write(campaign::result_file(dir_, 4), whole.substr(0, whole.size() - 1));  // torn: no final newline
  EXPECT_FALSE(campaign::read_result(dir_, 4, "spec four", r));
  EXPECT_THROW(campaign::write_result(dir_, 6, "s", "two\nlines"), std::invalid_argument);
}

TEST_F(TempDir, StateListsSubmissionsAndSkipsATornLine) {
  write(dir_ / "state.txt", "submit 41 0,1,2\nsubmit 57 2\nsubmit 60");
  const auto s = campaign::read_state(dir_);
  ASSERT_EQ(s.size(), 2u);
  EXPECT_EQ(s[0].first, "41");
  EXPECT_EQ(s[0].second, (std::vector<std::size_t>{0, 1, 2}));
  EXPECT_EQ(s[1].first, "57");
  EXPECT_EQ(s[1].second, (std::vector<std::size_t>{2}));
  EXPECT_TRUE(campaign::read_state(dir_ / "absent").empty());
}

TEST(CampaignScript, HasTheOptionsAndCallsTheWorker) {
  campaign::SlurmOptions o;
  o.partition = "short";
  o.account = "robotics";
  o.time = "00:10:00";
  o.cpus_per_task = 2;
  o.sbatch_options = {"--qos=low", "--mem=1G"};
  const std::string s = campaign::job_script("sweep", "/shared/c/sweep", o, "/opt/bin/tool");
  for (const char* line : {"#SBATCH --partition=short\n", "#SBATCH --account=robotics\n", "#SBATCH --time=00:10:00\n",
                           "#SBATCH --cpus-per-task=2\n", "#SBATCH --qos=low\n", "#SBATCH --mem=1G\n",
                           "#SBATCH --output=/shared/c/sweep/logs/%A_%a.out\n",
                           "exec '/opt/bin/tool' campaign-worker --dir '/shared/c/sweep' --task \"$SLURM_ARRAY_TASK_ID\"\n"})
    EXPECT_NE(s.find(line), std::string::npos) << line << " in\n" << s;
  EXPECT_EQ(campaign::job_script("x", "/d", campaign::SlurmOptions{}, "/t").find("--partition"), std::string::npos);
}

TEST_F(TempDir, YamlOptionsAreReadAndBadOnesNamed) {
  write(dir_ / "ok.yaml",
        "partition: gpu\naccount: lab\ntime: \"02:00:00\"\ncpus_per_task: 4\nsbatch_options: [\"--qos=x\"]\n"
        "chunk: 10\nthrottle: 50\nmax_retries: 1\npoll_s: 30\ndir: /scratch/c\n");
  campaign::SlurmOptions o;
  campaign::load_slurm_yaml(dir_ / "ok.yaml", o);
  EXPECT_EQ(o.partition, "gpu");
  EXPECT_EQ(o.account, "lab");
  EXPECT_EQ(o.time, "02:00:00");
  EXPECT_EQ(o.cpus_per_task, 4);
  EXPECT_EQ(o.sbatch_options, std::vector<std::string>{"--qos=x"});
  EXPECT_EQ(o.chunk, 10);
  EXPECT_EQ(o.throttle, 50);
  EXPECT_EQ(o.max_retries, 1);
  EXPECT_EQ(o.poll_s, 30.0);
  EXPECT_EQ(o.dir, fs::path("/scratch/c"));
  auto error_of = [&](const std::string& text) {
    write(dir_ / "bad.yaml", text);
    campaign::SlurmOptions x;
    try {
      campaign::load_slurm_yaml(dir_ / "bad.yaml", x);
    } catch (const pedalwave::config::ConfigError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const std::string typo = error_of("partiton: gpu\n");
  EXPECT_NE(typo.find("bad.yaml"), std::string::npos) << typo;
  EXPECT_NE(typo.find("partiton"), std::string::npos) << typo;
  const std::string chunk = error_of("chunk: 0\n");
  EXPECT_NE(chunk.find("chunk = \"0\": expected an integer in [1, 1000000]"), std::string::npos) << chunk;
  const std::string opt = error_of("sbatch_options: [\"qos=x\"]\n");
  EXPECT_NE(opt.find("sbatch_options"), std::string::npos) << opt;
  EXPECT_NE(opt.find("starting with --"), std::string::npos) << opt;
}

// ---- local backend -----------------------------------------------------------------------------------
TEST(CampaignLocal, ResultsComeInSpecificationOrderFromManyThreads) {
  std::vector<std::string> specs;
  for (int i = 0; i < 40; ++i) specs.push_back("run " + std::to_string(i) + std::string(static_cast<std::size_t>(i), 'x'));
  std::atomic<int> calls{0};
  campaign::Options o;
  o.jobs = 3;
  o.progress = false;
  const auto out = campaign::run("t", specs, [&](const std::string& s) { ++calls; return fake(s); }, o);
  ASSERT_EQ(out.size(), specs.size());
  for (std::size_t i = 0; i < specs.size(); ++i) EXPECT_EQ(out[i], fake(specs[i]));
  EXPECT_EQ(calls.load(), 40);
  EXPECT_THROW((void)campaign::run("t", {"a", "fail", "b"},
                                   [](const std::string& s) -> std::string {
                                     if (s == "fail") throw std::runtime_error("x");
                                     return s;
                                   },
                                   o),
               std::runtime_error);
}

TEST(CampaignPool, EveryItemOnceAndTheFirstExceptionRethrown) {
  std::vector<int> hits(50, 0);
  campaign::parallel_for(hits.size(), 3, [&](std::size_t i) { hits[i] += 1; });
  for (int h : hits) EXPECT_EQ(h, 1);
  EXPECT_THROW(campaign::parallel_for(10, 2, [](std::size_t i) { if (i == 4) throw std::runtime_error("x"); }),
               std::runtime_error);
  EXPECT_GE(campaign::default_jobs(), 1);
}

// ---- slurm backend against stand-ins ------------------------------------------------------------------
// sbatch: records "<job> <array>" in sbatch.log, prints the next job id, and runs the array's
// tasks at once (job.sh → the stand-in tool's worker), except that task t is "lost" (not run)
// as often as the file lose_<t> says. squeue: prints the file `queue` for its first `queue_for`
// calls, then nothing (every task left).
class SlurmStandIn : public TempDir {
 protected:
  void SetUp() override {
    TempDir::SetUp();
    bin_ = dir_ / "bin";
    fs::create_directories(bin_);
    write(bin_ / "sbatch",
          "#!/bin/sh\n"
          "b=$(dirname \"$0\")\n"
          "for a; do case $a in --array=*) arr=${a#--array=};; --parsable) ;; *) script=$a;; esac; done\n"
          "n=$(cat $b/next_id 2>/dev/null || echo 100); echo $((n + 1)) > $b/next_id\n"
          "echo \"$n $arr\" >> $b/sbatch.log\n"
          "arr=${arr%%\\%*}\n"
          "for part in $(echo $arr | tr , ' '); do\n"
          "  case $part in *-*) lo=${part%-*}; hi=${part#*-};; *) lo=$part; hi=$part;; esac\n"
          "  for t in $(seq $lo $hi); do\n"
          "    k=$(cat $b/lose_$t 2>/dev/null || echo 0)\n"
          "    if [ \"$k\" -gt 0 ]; then echo $((k - 1)) > $b/lose_$t; continue; fi\n"
          "    SLURM_ARRAY_TASK_ID=$t SLURM_ARRAY_JOB_ID=$n sh \"$script\" >/dev/null 2>&1\n"
          "  done\n"
          "done\n"
          "echo $n\n");
    write(bin_ / "squeue",
          "#!/bin/sh\n"
          "b=$(dirname \"$0\")\n"
          "c=$(cat $b/squeue_calls 2>/dev/null || echo 0); echo $((c + 1)) > $b/squeue_calls\n"
          "if [ \"$c\" -lt \"$(cat $b/queue_for 2>/dev/null || echo 0)\" ]; then cat $b/queue; fi\n");
    for (const char* f : {"sbatch", "squeue"})
      fs::permissions(bin_ / f, fs::perms::owner_all, fs::perm_options::add);
    o_.backend = campaign::Backend::slurm;
    o_.progress = false;
    o_.log = &log_;
    o_.slurm.dir = dir_ / "c";
    o_.slurm.sbatch = (bin_ / "sbatch").string();
    o_.slurm.squeue = (bin_ / "squeue").string();
    o_.slurm.sacct = "false";
    o_.slurm.poll_s = 0.01;
    o_.slurm.worker_exe = PEDALWAVE_CAMPAIGN_FAKE_TOOL;
  }
  std::vector<std::string> specs(int n) const {
    std::vector<std::string> s;
    for (int i = 0; i < n; ++i) s.push_back("k_c=" + campaign::hex(0.1 * i));
    return s;
  }
  fs::path bin_;
  std::ostringstream log_;
  campaign::Options o_;
};

TEST_F(SlurmStandIn, GathersEveryResultInOrderFromChunkedArrayTasks) {
  o_.slurm.chunk = 3;
  o_.slurm.throttle = 2;
  const auto s = specs(7);
  const auto out = campaign::run("sweep", s, fake, o_);
  ASSERT_EQ(out.size(), s.size());
  for (std::size_t i = 0; i < s.size(); ++i) EXPECT_EQ(out[i], fake(s[i]));
  EXPECT_EQ(slurp(bin_ / "sbatch.log"), "100 0-2%2\n");  // one submission: 3 tasks, throttle 2
  const std::string runs = slurp(dir_ / "c" / "sweep" / "runs.log");
  for (int i = 0; i < 7; ++i) EXPECT_EQ(count_lines(runs, "run " + std::to_string(i) + " "), 1) << runs;
  EXPECT_NE(runs.find("run 6 task 2 job 100"), std::string::npos) << runs;
}

TEST_F(SlurmStandIn, ALostTaskIsResubmittedAndOnlyItsRunsRunAgain) {
  o_.slurm.chunk = 2;
  write(bin_ / "lose_1", "1");  // task 1 (runs 2, 3) is lost once
  const auto s = specs(6);
  const auto out = campaign::run("sweep", s, fake, o_);
  for (std::size_t i = 0; i < s.size(); ++i) EXPECT_EQ(out[i], fake(s[i]));
  EXPECT_EQ(slurp(bin_ / "sbatch.log"), "100 0-2\n101 1\n");
  EXPECT_NE(log_.str().find("array task 1 of job 100 ended without its results: resubmitting (retry 1 of 2)"),
            std::string::npos)
      << log_.str();
  const std::string runs = slurp(dir_ / "c" / "sweep" / "runs.log");
  for (int i = 0; i < 6; ++i) EXPECT_EQ(count_lines(runs, "run " + std::to_string(i) + " "), 1) << runs;
}

TEST_F(SlurmStandIn, ATaskLostMoreThanMaxRetriesFailsTheCampaignNamingIt) {
  o_.slurm.chunk = 2;
  o_.slurm.max_retries = 1;
  write(bin_ / "lose_2", "5");
  try {
    (void)campaign::run("sweep", specs(6), fake, o_);
    FAIL() << "expected the campaign to fail";
  } catch (const std::runtime_error& e) {
    const std::string w = e.what();
    EXPECT_NE(w.find("array task 2 (runs 4 … 5) ended without its results 2 times (max_retries 1)"), std::string::npos)
        << w;
    EXPECT_NE(w.find("logs/101_2.out"), std::string::npos) << w;
  }
  EXPECT_EQ(slurp(bin_ / "sbatch.log"), "100 0-2\n101 2\n");
}

TEST_F(SlurmStandIn, AFailingRunFailsItsTaskUpToTheRetries) {
  o_.slurm.max_retries = 0;
  EXPECT_THROW((void)campaign::run("sweep", {"a", "fail"}, fake, o_), std::runtime_error);
  const std::string task_log = slurp(dir_ / "c" / "sweep" / "runs.log");
  EXPECT_EQ(count_lines(task_log, "run 0 "), 1);
  EXPECT_EQ(count_lines(task_log, "run 1 "), 0);
}

TEST_F(SlurmStandIn, ResumeKeepsFinishedRunsFollowsQueuedTasksAndResubmitsLostOnes) {
  // The interrupted campaign: job 42 had tasks 0, 1, 2 (chunk 2); task 0 finished, task 1 is
  // still running (in the queue for the first 3 squeue calls, then gone without results: lost),
  // task 2 ended without results while nobody watched.
  o_.slurm.chunk = 2;
  const auto s = specs(6);
  const fs::path c = dir_ / "c" / "sweep";
  fs::create_directories(c / "results");
  std::string text;
  for (const std::string& x : s) text += x + "\n";
  write(c / "specs.txt", text);
  write(c / "state.txt", "submit 42 0,1,2\n");
  campaign::write_result(c, 0, s[0], fake(s[0]));
  campaign::write_result(c, 1, s[1], fake(s[1]));
  write(bin_ / "queue", "42 1 RUNNING\n");
  write(bin_ / "queue_for", "3");
  const auto out = campaign::run("sweep", s, fake, o_);
  for (std::size_t i = 0; i < s.size(); ++i) EXPECT_EQ(out[i], fake(s[i]));
  EXPECT_NE(log_.str().find("resuming: 2 runs done, 1 submissions recorded"), std::string::npos) << log_.str();
  // Task 2 once it was seen gone; task 1 only after it left the queue.
  EXPECT_EQ(slurp(bin_ / "sbatch.log"), "100 2\n101 1\n");
  const std::string runs = slurp(c / "runs.log");
  EXPECT_EQ(count_lines(runs, "run 0 "), 0) << runs;  // finished before: not rerun
  EXPECT_EQ(count_lines(runs, "run 1 "), 0) << runs;
  for (int i = 2; i < 6; ++i) EXPECT_EQ(count_lines(runs, "run " + std::to_string(i) + " "), 1) << runs;
}

TEST_F(SlurmStandIn, AnotherCampaignInTheFolderIsReplacedUnlessItsJobsRun) {
  const fs::path c = dir_ / "c" / "sweep";
  (void)campaign::run("sweep", specs(2), fake, o_);
  ASSERT_TRUE(fs::exists(campaign::result_file(c, 1)));
  // A different campaign under the same name while the old job still runs: refused.
  write(bin_ / "queue", "100 0 RUNNING\n");
  write(bin_ / "squeue_calls", "0");
  write(bin_ / "queue_for", "1");
  try {
    (void)campaign::run("sweep", specs(3), fake, o_);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("is still queued or running: scancel 100"), std::string::npos) << e.what();
  }
  // Once it is gone: the old results are removed, the new campaign runs whole.
  const auto s3 = specs(3);
  const auto out = campaign::run("sweep", s3, fake, o_);
  for (std::size_t i = 0; i < s3.size(); ++i) EXPECT_EQ(out[i], fake(s3[i]));
  EXPECT_EQ(count_lines(slurp(c / "runs.log"), "run "), 3);
}

TEST_F(SlurmStandIn, SbatchRefusingIsAnErrorWithItsMessage) {
  write(bin_ / "sbatch", "#!/bin/sh\necho 'sbatch: error: Invalid partition name specified' >&2\nexit 1\n");
  try {
    (void)campaign::run("sweep", specs(1), fake, o_);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("failed (exit 1): sbatch: error: Invalid partition name specified"),
              std::string::npos)
        << e.what();
  }
}
