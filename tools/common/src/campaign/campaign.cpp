// The backends of a campaign (campaign.hpp): local thread pool, Slurm job arrays, the array
// task's worker entry.
#include "pedalwave/campaign/campaign.hpp"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <set>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "pedalwave/config/yaml_reader.hpp"
#include "pedalwave/toolkit/progress.hpp"

namespace pedalwave::campaign {

namespace fs = std::filesystem;
namespace tk = pedalwave::toolkit;

namespace {

std::ostream& log_of(const Options& o) { return o.log ? *o.log : std::cerr; }

// Single-quoted for /bin/sh.
std::string quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

struct CommandOutput {
  int status = -1;   // exit status (−1: could not start)
  std::string text;  // stdout and stderr
};

CommandOutput command(const std::vector<std::string>& argv) {
  std::string line;
  for (const std::string& a : argv) line += (line.empty() ? "" : " ") + quote(a);
  line += " 2>&1";
  CommandOutput out;
  FILE* p = ::popen(line.c_str(), "r");
  if (!p) return out;
  char buf[4096];
  for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, p)) > 0;) out.text.append(buf, n);
  const int st = ::pclose(p);
  out.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return out;
}

std::string one_line(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  for (char& c : s)
    if (c == '\n') c = ' ';
  return s;
}

std::string read_text(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  if (!f) return {};
  std::ostringstream os;
  os << f.rdbuf();
  return os.str();
}

// Writes through a temporary file and a rename: a reader sees the old file or the whole new one.
void write_atomically(const fs::path& p, const std::string& text) {
  const fs::path tmp = p.string() + ".tmp." + std::to_string(::getpid());
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    f << text;
    f.flush();
    if (!f) throw std::runtime_error("cannot write " + tmp.string());
  }
  fs::rename(tmp, p);
}

void append_line(const fs::path& p, const std::string& line) {
  std::ofstream f(p, std::ios::app);
  f << line << '\n';
  f.flush();
  if (!f) throw std::runtime_error("cannot write " + p.string());
}

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream is(text);
  for (std::string l; std::getline(is, l);) out.push_back(l);
  return out;
}

std::string specs_text(const std::vector<std::string>& specs) {
  std::string t;
  for (const std::string& s : specs) {
    if (s.find('\n') != std::string::npos) throw std::invalid_argument("campaign: a specification holds a newline");
    t += s;
    t += '\n';
  }
  return t;
}

fs::path self_exe() {
  std::error_code ec;
  const fs::path p = fs::read_symlink("/proc/self/exe", ec);
  if (ec) throw std::runtime_error("cannot find this program's path (/proc/self/exe): " + ec.message());
  return p;
}

// ---- local ---------------------------------------------------------------------------------------
std::vector<std::string> run_local(const std::string& name, const std::vector<std::string>& specs,
                                   const Runner& runner, const Options& o) {
  std::vector<std::string> out(specs.size());
  tk::Progress progress(name, specs.size(),
                        tk::Progress::Options{.style = o.progress ? tk::Progress::Style::automatic
                                                                  : tk::Progress::Style::silent});
  parallel_for(
      specs.size(), o.jobs, [&](std::size_t i) { out[i] = runner(specs[i]); }, [&]() { progress.advance(); });
  progress.finish();
  return out;
}

// ---- slurm ---------------------------------------------------------------------------------------
// Tasks of `job` still in the queue (pending, running, completing, …); ok = false when squeue
// failed for another reason than a job the controller no longer knows.
struct QueueView {
  bool ok = true;
  std::string error;
  std::set<std::size_t> tasks;
};

QueueView queued_tasks(const SlurmOptions& o, const std::string& job) {
  QueueView v;
  const CommandOutput r = command({o.squeue, "-h", "-r", "-j", job, "-o", "%F %K %T"});
  if (r.status != 0) {
    if (r.text.find("Invalid job id") != std::string::npos) return v;  // long gone
    v.ok = false;
    v.error = o.squeue + " -j " + job + ": " + one_line(r.text) + " (exit " + std::to_string(r.status) + ")";
    return v;
  }
  for (const std::string& l : lines_of(r.text)) {
    std::istringstream is(l);
    std::string id, task, state;
    if (!(is >> id >> task >> state) || id != job) continue;
    char* end = nullptr;
    const unsigned long long t = std::strtoull(task.c_str(), &end, 10);
    if (end != task.c_str() && *end == '\0') v.tasks.insert(static_cast<std::size_t>(t));
  }
  return v;
}

// Why a task ended, from accounting when the cluster keeps it ("" when it does not).
std::string accounting_state(const SlurmOptions& o, const std::string& job, std::size_t task) {
  const CommandOutput r =
      command({o.sacct, "-n", "-X", "-P", "-j", job + "_" + std::to_string(task), "-o", "State,ExitCode"});
  if (r.status != 0) return "";
  const auto ls = lines_of(r.text);
  return ls.empty() ? "" : one_line(ls.front());
}

std::string submit(const SlurmOptions& o, const fs::path& dir, const std::vector<std::size_t>& tasks) {
  std::string array = array_ranges(tasks);
  if (o.throttle > 0) array += "%" + std::to_string(o.throttle);
  const CommandOutput r = command({o.sbatch, "--parsable", "--array=" + array, (dir / "job.sh").string()});
  std::string id;
  for (const std::string& l : lines_of(r.text))
    if (!l.empty()) id = l;
  id = id.substr(0, id.find(';'));
  const bool digits = !id.empty() && std::all_of(id.begin(), id.end(), [](char c) { return c >= '0' && c <= '9'; });
  if (r.status != 0 || !digits)
    throw std::runtime_error(o.sbatch + " --array=" + array + " " + (dir / "job.sh").string() + " failed (exit " +
                             std::to_string(r.status) + "): " + one_line(r.text));
  append_line(dir / "state.txt", "submit " + id + " " + [&] {
    std::string t;
    for (std::size_t x : tasks) t += (t.empty() ? "" : ",") + std::to_string(x);
    return t;
  }());
  return id;
}

// Prepares dir for these specifications: a new campaign, or the same one again (resume).
// Returns true when resuming.
bool prepare(const std::string& name, const fs::path& dir, const std::vector<std::string>& specs,
             const SlurmOptions& o, const fs::path& exe) {
  fs::create_directories(dir);
  const std::string text = specs_text(specs);
  const bool exists = fs::exists(dir / "specs.txt");
  const bool same = exists && read_text(dir / "specs.txt") == text;
  if (exists && !same) {
    // Another campaign was here: refuse while its jobs run (they would write into it).
    for (const auto& [job, tasks] : read_state(dir)) {
      const QueueView q = queued_tasks(o, job);
      if (!q.ok || !q.tasks.empty())
        throw std::runtime_error("campaign folder " + dir.string() + " holds another campaign whose job " + job +
                                 " is still queued or running: scancel " + job + " or choose another folder");
    }
    fs::remove_all(dir / "results");
    fs::remove_all(dir / "logs");
    fs::remove(dir / "state.txt");
    fs::remove(dir / "runs.log");
  }
  fs::create_directories(dir / "results");
  fs::create_directories(dir / "logs");
  if (!same) write_atomically(dir / "specs.txt", text);
  Record info;
  info.put_text("name", name)
      .put_int("runs", static_cast<long long>(specs.size()))
      .put_int("chunk", o.chunk)
      .put_int("tasks", static_cast<long long>(task_count(specs.size(), o.chunk)))
      .put_text("worker", exe.string());
  write_atomically(dir / "campaign.txt", info.line() + "\n");
  write_atomically(dir / "job.sh", job_script(name, dir, o, exe));
  fs::permissions(dir / "job.sh", fs::perms::owner_all, fs::perm_options::add);
  return same;
}

std::vector<std::string> run_slurm(const std::string& name, const std::vector<std::string>& specs,
                                   const Options& opt) {
  const SlurmOptions& o = opt.slurm;
  if (o.chunk < 1) throw std::invalid_argument("--chunk " + std::to_string(o.chunk) + ": expected ≥ 1");
  if (o.max_retries < 0) throw std::invalid_argument("--max-retries " + std::to_string(o.max_retries) + ": expected ≥ 0");
  const fs::path dir = fs::absolute(o.dir / name);
  const fs::path exe = o.worker_exe.empty() ? self_exe() : fs::absolute(o.worker_exe);
  const bool resuming = prepare(name, dir, specs, o, exe);
  const std::size_t n = specs.size(), n_tasks = task_count(n, o.chunk);
  std::ostream& log = log_of(opt);

  std::vector<std::string> results(n);
  std::vector<bool> have(n, false);
  std::size_t done = 0;
  auto collect = [&] {
    for (std::size_t i = 0; i < n; ++i)
      if (!have[i] && read_result(dir, i, specs[i], results[i])) {
        have[i] = true;
        ++done;
      }
  };
  auto task_done = [&](std::size_t t) {
    const auto [a, b] = task_runs(t, n, o.chunk);
    for (std::size_t i = a; i < b; ++i)
      if (!have[i]) return false;
    return true;
  };

  // Submissions so far (a resumed campaign's state.txt): per task, how often and the last job.
  std::vector<std::pair<std::string, std::vector<std::size_t>>> jobs = read_state(dir);
  std::vector<int> attempts(n_tasks, 0), missing(n_tasks, 0);
  std::vector<std::string> last_job(n_tasks);
  for (const auto& [job, tasks] : jobs)
    for (std::size_t t : tasks)
      if (t < n_tasks) {
        ++attempts[t];
        last_job[t] = job;
      }
  collect();
  log << name << ": campaign " << dir.string() << ", " << n << " runs in " << n_tasks << " array tasks of "
      << o.chunk << (resuming ? " (resuming: " + std::to_string(done) + " runs done, " + std::to_string(jobs.size()) +
                                    " submissions recorded)"
                              : std::string())
      << '\n';

  tk::Progress progress(name, n,
                        tk::Progress::Options{.style = opt.progress ? tk::Progress::Style::automatic
                                                                    : tk::Progress::Style::silent});
  std::size_t shown = 0;
  int queue_failures = 0;
  for (;;) {
    // The queue first, then the results: a task that left the queue wrote its results before.
    std::set<std::size_t> active;
    bool queue_ok = true;
    for (const auto& [job, tasks] : jobs) {
      const QueueView q = queued_tasks(o, job);
      if (!q.ok) {
        queue_ok = false;
        if (++queue_failures % 12 == 1) log << name << ": " << q.error << " (retrying)\n";
        break;
      }
      active.insert(q.tasks.begin(), q.tasks.end());
    }
    if (queue_ok) queue_failures = 0;
    collect();
    if (done > shown) {
      progress.advance(done - shown);
      shown = done;
    }
    if (done == n) break;

    if (queue_ok) {
      std::vector<std::size_t> fresh, lost;
      for (std::size_t t = 0; t < n_tasks; ++t) {
        if (task_done(t) || active.count(t)) {
          missing[t] = 0;
          continue;
        }
        if (attempts[t] == 0) {
          fresh.push_back(t);
        } else if (++missing[t] >= 2) {  // out of the queue without its results on two polls
          lost.push_back(t);
        }
      }
      for (std::size_t t : lost) {
        const auto [a, b] = task_runs(t, n, o.chunk);
        const std::string why = accounting_state(o, last_job[t], t);
        const std::string where = (dir / "logs" / (last_job[t] + "_" + std::to_string(t) + ".out")).string();
        if (attempts[t] > o.max_retries) {
          progress.finish();
          throw std::runtime_error(name + ": array task " + std::to_string(t) + " (runs " + std::to_string(a) + " … " +
                                   std::to_string(b - 1) + ") ended without its results " + std::to_string(attempts[t]) +
                                   " times (max_retries " + std::to_string(o.max_retries) + ")" +
                                   (why.empty() ? "" : ", last state " + why) + "; see " + where);
        }
        log << name << ": array task " << t << " of job " << last_job[t] << " ended without its results"
            << (why.empty() ? "" : " (" + why + ")") << ": resubmitting (retry " << attempts[t] << " of "
            << o.max_retries << ")\n";
      }
      std::vector<std::size_t> to_submit = fresh;
      to_submit.insert(to_submit.end(), lost.begin(), lost.end());
      std::sort(to_submit.begin(), to_submit.end());
      if (!to_submit.empty()) {
        const std::string job = submit(o, dir, to_submit);
        jobs.emplace_back(job, to_submit);
        for (std::size_t t : to_submit) {
          ++attempts[t];
          missing[t] = 0;
          last_job[t] = job;
        }
        log << name << ": submitted job " << job << " (array " << array_ranges(to_submit) << ")\n";
        continue;  // look at the queue at once
      }
    }
    std::this_thread::sleep_for(std::chrono::duration<double>(o.poll_s));
  }
  progress.finish();
  return results;
}

}  // namespace

// ---- public pieces -------------------------------------------------------------------------------
std::size_t task_count(std::size_t runs, int chunk) {
  const auto c = static_cast<std::size_t>(std::max(1, chunk));
  return (runs + c - 1) / c;
}

std::pair<std::size_t, std::size_t> task_runs(std::size_t task, std::size_t runs, int chunk) {
  const auto c = static_cast<std::size_t>(std::max(1, chunk));
  const std::size_t a = std::min(runs, task * c);
  return {a, std::min(runs, a + c)};
}

std::string array_ranges(const std::vector<std::size_t>& tasks) {
  std::string out;
  for (std::size_t i = 0; i < tasks.size();) {
    std::size_t j = i;
    while (j + 1 < tasks.size() && tasks[j + 1] == tasks[j] + 1) ++j;
    if (!out.empty()) out += ',';
    out += std::to_string(tasks[i]);
    if (j > i) out += "-" + std::to_string(tasks[j]);
    i = j + 1;
  }
  return out;
}

std::string job_script(const std::string& name, const fs::path& dir, const SlurmOptions& o, const fs::path& exe) {
  std::ostringstream s;
  s << "#!/bin/sh\n"
    << "# pedalwave campaign '" << name << "': array task I runs runs I*" << o.chunk << " … of " << dir.string()
    << "/specs.txt\n"
    << "#SBATCH --job-name=pw-" << name << '\n'
    << "#SBATCH --output=" << (dir / "logs").string() << "/%A_%a.out\n"
    << "#SBATCH --cpus-per-task=" << o.cpus_per_task << '\n';
  if (!o.partition.empty()) s << "#SBATCH --partition=" << o.partition << '\n';
  if (!o.account.empty()) s << "#SBATCH --account=" << o.account << '\n';
  if (!o.time.empty()) s << "#SBATCH --time=" << o.time << '\n';
  for (const std::string& x : o.sbatch_options) s << "#SBATCH " << x << '\n';
  s << "exec " << quote(exe.string()) << " campaign-worker --dir " << quote(dir.string())
    << " --task \"$SLURM_ARRAY_TASK_ID\"\n";
  return s.str();
}

fs::path result_file(const fs::path& dir, std::size_t i) {
  return dir / "results" / (std::to_string(i) + ".res");
}

bool read_result(const fs::path& dir, std::size_t i, const std::string& spec, std::string& result) {
  const std::string text = read_text(result_file(dir, i));
  const std::string head = "spec " + hash(spec) + "\n";
  if (text.size() < head.size() + 1 || text.compare(0, head.size(), head) != 0 || text.back() != '\n') return false;
  result = text.substr(head.size(), text.size() - head.size() - 1);
  return true;
}

void write_result(const fs::path& dir, std::size_t i, const std::string& spec, const std::string& result) {
  if (result.find('\n') != std::string::npos) throw std::invalid_argument("campaign: a result holds a newline");
  write_atomically(result_file(dir, i), "spec " + hash(spec) + "\n" + result + "\n");
}

std::vector<std::pair<std::string, std::vector<std::size_t>>> read_state(const fs::path& dir) {
  std::vector<std::pair<std::string, std::vector<std::size_t>>> out;
  for (const std::string& l : lines_of(read_text(dir / "state.txt"))) {
    std::istringstream is(l);
    std::string word, job, list;
    if (!(is >> word >> job >> list) || word != "submit") continue;  // a torn last line
    std::vector<std::size_t> tasks;
    std::istringstream ls(list);
    for (std::string t; std::getline(ls, t, ',');)
      if (!t.empty()) tasks.push_back(static_cast<std::size_t>(std::strtoull(t.c_str(), nullptr, 10)));
    out.emplace_back(job, std::move(tasks));
  }
  return out;
}

void load_slurm_yaml(const fs::path& file, SlurmOptions& o) {
  const config::Reader r = config::Reader::load_file(file.string());
  r.allow_only({"partition", "account", "time", "cpus_per_task", "sbatch_options", "chunk", "throttle",
                "max_retries", "poll_s", "dir"});
  o.partition = r.string("partition", o.partition);
  o.account = r.string("account", o.account);
  o.time = r.string("time", o.time);
  o.cpus_per_task = static_cast<int>(r.integer("cpus_per_task", o.cpus_per_task, 1, 4096));
  o.chunk = static_cast<int>(r.integer("chunk", o.chunk, 1, 1000000));
  o.throttle = static_cast<int>(r.integer("throttle", o.throttle, 0, 1000000));
  o.max_retries = static_cast<int>(r.integer("max_retries", o.max_retries, 0, 100));
  o.poll_s = r.bounded("poll_s", o.poll_s, 0.0, 3600.0, "s", true);
  if (r.has("dir")) o.dir = r.string("dir", o.dir.string());
  if (r.has("sbatch_options")) {
    const config::Reader l = r["sbatch_options"];
    if (!l.is_sequence()) l.fail("a list of sbatch options, e.g. [\"--qos=long\"]");
    o.sbatch_options.clear();
    for (std::size_t i = 0; i < l.size(); ++i) {
      const std::string x = l.at(i).as_string();
      if (x.rfind("--", 0) != 0 || x.find('\n') != std::string::npos)
        l.at(i).fail("an sbatch option starting with -- on one line");
      o.sbatch_options.push_back(x);
    }
  }
}

std::vector<std::string> run(const std::string& name, const std::vector<std::string>& specs, const Runner& runner,
                             const Options& o) {
  if (o.backend == Backend::slurm) return run_slurm(name, specs, o);
  return run_local(name, specs, runner, o);
}

int worker_main(int argc, char** argv, const Runner& runner, std::string_view tool) {
  const std::string who = std::string(tool) + " campaign-worker";
  fs::path dir;
  std::string task_text = std::getenv("SLURM_ARRAY_TASK_ID") ? std::getenv("SLURM_ARRAY_TASK_ID") : "";
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if ((a == "--dir" || a == "--task") && i + 1 < argc) {
      if (a == "--dir") dir = argv[i + 1];
      else task_text = argv[i + 1];
      ++i;
    } else {
      std::cerr << who << ": error: '" << a << "': expected --dir DIR [--task I]\n";
      return 2;
    }
  }
  char* end = nullptr;
  const unsigned long long task = std::strtoull(task_text.c_str(), &end, 10);
  if (dir.empty() || task_text.empty() || *end != '\0') {
    std::cerr << who << ": error: --task '" << task_text << "' and --dir '" << dir.string()
              << "': expected a campaign folder and a task number (or $SLURM_ARRAY_TASK_ID)\n";
    return 2;
  }
  try {
    const std::vector<std::string> info_lines = lines_of(read_text(dir / "campaign.txt"));
    if (info_lines.empty()) throw std::invalid_argument((dir / "campaign.txt").string() + ": missing or empty");
    const Record info = Record::parse(info_lines.front(), (dir / "campaign.txt").string());
    const int chunk = static_cast<int>(info.integer("chunk"));
    const std::vector<std::string> specs = lines_of(read_text(dir / "specs.txt"));
    if (static_cast<long long>(specs.size()) != info.integer("runs"))
      throw std::invalid_argument((dir / "specs.txt").string() + ": " + std::to_string(specs.size()) +
                                  " lines: expected " + std::to_string(info.integer("runs")));
    const auto [a, b] = task_runs(static_cast<std::size_t>(task), specs.size(), chunk);
    if (a == b) throw std::invalid_argument("--task " + task_text + ": the campaign has fewer tasks");
    char host[256] = {};
    ::gethostname(host, sizeof host - 1);
    const char* job = std::getenv("SLURM_ARRAY_JOB_ID");
    for (std::size_t i = a; i < b; ++i) {
      std::string old;
      if (read_result(dir, i, specs[i], old)) continue;  // done by an earlier attempt
      const std::string result = runner(specs[i]);
      write_result(dir, i, specs[i], result);
      append_line(dir / "runs.log", "run " + std::to_string(i) + " task " + task_text + " job " +
                                        (job ? job : "-") + " host " + host);
    }
  } catch (const std::exception& e) {
    std::cerr << who << ": error: " << e.what() << '\n';
    return 1;
  }
  return 0;
}

}  // namespace pedalwave::campaign
