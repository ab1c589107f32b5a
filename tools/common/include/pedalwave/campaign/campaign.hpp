// pedalwave::campaign — many independent simulations, on this machine or on a Slurm cluster.
//
// A campaign is a list of run specifications, each one line of text (a Record: tab-separated
// key=value fields, doubles as hex floats, so the text holds every bit); a runner turns one
// specification into one result line. A run depends only on its specification, never on where
// or when it runs, so the backends give bit-identical results:
//   local  the one thread pool of the tools (parallel_for) with a progress bar (the default);
//   slurm  writes the specifications and an sbatch job-array script into a campaign folder,
//          submits them (`sbatch --array=…%throttle`, `chunk` runs per array task), follows them
//          with squeue (sacct, when the cluster keeps accounting, names why a task ended), shows
//          the same progress bar, resubmits a task that left the queue without its results
//          (killed, node lost) at most `max_retries` times, and gathers the results in run order.
// The array task runs the same tool binary: `<tool> campaign-worker --dir DIR --task I`
// (worker_main), which writes one result file per run (atomically: write, then rename).
// Resumable: run the same command again after the submitting process was interrupted; finished
// runs (result files whose specification hash matches) are kept, queued and running tasks are
// followed, not submitted twice.
//
// Campaign folder (SlurmOptions' dir/<name>):
//   specs.txt        one specification per line (run i = line i)
//   campaign.txt     runs, chunk, tasks, worker command
//   job.sh           the sbatch script (#SBATCH lines from SlurmOptions)
//   state.txt        one line per submission: "submit <job id> <task,task,…>"
//   results/<i>.res  first line "spec <hash of spec i>", second line the result
//   runs.log         one line per run a worker executed ("run <i> task <t> job <id> host <h>")
//   logs/            the array tasks' stdout/stderr (%A_%a.out)
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <iosfwd>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace pedalwave::campaign {

// ---- the one thread pool ---------------------------------------------------------------------------
// Runs f(i) for i = 0 … n−1 on `jobs` threads (1 = in the calling thread), taking items in order
// from a shared counter; `done` (may be empty) is called after each item, from the worker. The
// first exception thrown by f is rethrown after all threads stopped (no new item starts after it).
void parallel_for(std::size_t n, int jobs, const std::function<void(std::size_t)>& f,
                  const std::function<void()>& done = {});
// The number of hardware threads (at least 1).
int default_jobs();

// ---- exact one-line records ------------------------------------------------------------------------
// "%a" hex float ("nan", "inf", "-inf" for the non-finite): strtod reads back the same bits
// (a NaN reads back as the quiet NaN).
std::string hex(double v);
// Text without tab, newline, carriage return or '%' (those become %09 %0A %0D %25), and back.
std::string escape(std::string_view text);
std::string unescape(std::string_view text);
// 64-bit FNV-1a of the text, 16 hex digits.
std::string hash(std::string_view text);

// Tab-separated key=value fields in the order they were put. Getters throw std::invalid_argument
// naming the key, the value and the expectation (`context` says which record: file and line).
class Record {
 public:
  Record& put(const std::string& key, double v);
  Record& put_int(const std::string& key, long long v);
  Record& put_text(const std::string& key, std::string_view v);
  [[nodiscard]] std::string line() const;

  static Record parse(std::string_view line, std::string context);
  [[nodiscard]] bool has(const std::string& key) const;
  [[nodiscard]] double number(const std::string& key) const;
  [[nodiscard]] long long integer(const std::string& key) const;
  [[nodiscard]] std::string text(const std::string& key) const;

 private:
  [[nodiscard]] const std::string& raw(const std::string& key) const;
  std::vector<std::pair<std::string, std::string>> fields_;  // key, escaped value
  std::string context_;
};

// ---- backends --------------------------------------------------------------------------------------
enum class Backend { local, slurm };
Backend parse_backend(const std::string& name);  // "local" | "slurm", else std::invalid_argument

struct SlurmOptions {
  std::filesystem::path dir = "campaign";  // campaign folders go to dir/<name> (shared file system)
  std::string partition, account;          // empty = the cluster's default
  std::string time;                        // per array task, sbatch --time (e.g. 01:00:00); empty = default
  int cpus_per_task = 1;
  std::vector<std::string> sbatch_options; // extra #SBATCH options, each e.g. "--qos=long"
  int chunk = 1;                           // runs per array task (≥ 1)
  int throttle = 0;                        // most array tasks running at once (%N); 0 = no limit
  int max_retries = 2;                     // resubmissions of one task before the campaign fails
  double poll_s = 5.0;                     // between squeue queries [s]
  std::string sbatch = "sbatch", squeue = "squeue", sacct = "sacct";  // the commands
  std::filesystem::path worker_exe;        // the tool binary; empty = this process's (/proc/self/exe)
};
// Reads a small YAML file into `o` (keys: partition, account, time, cpus_per_task, sbatch_options
// (a list), chunk, throttle, max_retries, poll_s, dir). Errors (config::ConfigError) name the file,
// the line, the key, the value and what was expected.
void load_slurm_yaml(const std::filesystem::path& file, SlurmOptions& o);

struct Options {
  Backend backend = Backend::local;
  int jobs = 1;                // local: threads
  bool progress = true;        // progress bar on stderr
  SlurmOptions slurm;
  std::ostream* log = nullptr; // what the slurm backend reports (submissions, resubmissions); nullptr = std::cerr
};

// Turns one specification into one result line (no newline). Must be deterministic; may throw.
using Runner = std::function<std::string(const std::string& spec)>;

// Runs every specification with the chosen backend; the results in specification order.
// `name` labels the progress bar and names the campaign folder (slurm). A specification must be
// one line (no '\n'). The slurm backend throws std::runtime_error when sbatch refuses the job or
// a task failed more than max_retries times (naming the task, its runs and its log file).
std::vector<std::string> run(const std::string& name, const std::vector<std::string>& specs,
                             const Runner& runner, const Options& o);

// The array task's entry: `<tool> campaign-worker --dir DIR [--task I]` (argv[0] is
// "campaign-worker"; the task defaults to $SLURM_ARRAY_TASK_ID). Runs the task's runs that have
// no result yet. Returns the exit status (0; 2 bad arguments; 1 a run threw, with its message).
int worker_main(int argc, char** argv, const Runner& runner, std::string_view tool);

// ---- pieces of the slurm backend, exposed for tests ---------------------------------------------------
// Tasks of a campaign of n runs in chunks of `chunk`: ceil(n / chunk); the runs of task t.
std::size_t task_count(std::size_t runs, int chunk);
std::pair<std::size_t, std::size_t> task_runs(std::size_t task, std::size_t runs, int chunk);  // [first, last)
// "1-3,7,9-10" for sorted tasks.
std::string array_ranges(const std::vector<std::size_t>& tasks);
// The sbatch script for the campaign folder `dir`.
std::string job_script(const std::string& name, const std::filesystem::path& dir, const SlurmOptions& o,
                       const std::filesystem::path& worker_exe);
// Result file of run i (dir/results/<i>.res). read_result: true and the result of run i when its
// file is whole and was written for `spec` (the hash on its first line matches), else false.
// write_result writes it atomically (a temporary file, then a rename).
std::filesystem::path result_file(const std::filesystem::path& dir, std::size_t i);
bool read_result(const std::filesystem::path& dir, std::size_t i, const std::string& spec, std::string& result);
void write_result(const std::filesystem::path& dir, std::size_t i, const std::string& spec, const std::string& result);
// Submissions recorded in dir/state.txt: job id → tasks.
std::vector<std::pair<std::string, std::vector<std::size_t>>> read_state(const std::filesystem::path& dir);

}  // namespace pedalwave::campaign
