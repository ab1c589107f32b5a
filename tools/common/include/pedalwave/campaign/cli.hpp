// The campaign options every campaign tool shares (pedalwave_paper, pedalwave_workprec,
// pedalwave_faultbench), written once, and the hidden worker entry of the array tasks.
//
//   --backend local|slurm   --slurm-config FILE.yaml   --campaign-dir DIR
//   --partition P --account A --time T --cpus-per-task N --sbatch-opt "--qos=x" (repeatable)
//   --chunk N --throttle N --max-retries N --poll S
// Options given on the command line win over the YAML file's keys.
// Header-only over CLI11 (a tool links pedalwave::cli and pedalwave::campaign).
#pragma once

#include <CLI/CLI.hpp>

#include <string>
#include <string_view>
#include <vector>

#include "pedalwave/campaign/campaign.hpp"

namespace pedalwave::campaign::cli {

struct CliOptions {
  std::string backend = "local";
  std::string slurm_config;  // YAML file; empty = none
  SlurmOptions slurm;        // what the command line gave (the rest: defaults or the file)
  CLI::App* app = nullptr;   // to ask which options were given
};

inline void add_options(CLI::App* app, CliOptions& c, const std::string& default_dir) {
  c.app = app;
  c.slurm.dir = default_dir;
  app->add_option("--backend", c.backend, "where the independent runs go: local (threads) or slurm (job arrays)")
      ->check(CLI::IsMember({"local", "slurm"}))->capture_default_str()->group("Campaign");
  app->add_option("--slurm-config", c.slurm_config,
                  "YAML file of slurm options (partition, account, time, cpus_per_task, sbatch_options, chunk, "
                  "throttle, max_retries, poll_s, dir)")->group("Campaign");
  app->add_option("--campaign-dir", c.slurm.dir,
                  std::string("slurm: campaign folders (on a file system the nodes share)") +
                      (default_dir.empty() ? "; default <--out>/campaign" : ""))
      ->capture_default_str()->group("Campaign");
  app->add_option("--partition", c.slurm.partition, "slurm: partition")->group("Campaign");
  app->add_option("--account", c.slurm.account, "slurm: account")->group("Campaign");
  app->add_option("--time", c.slurm.time, "slurm: time limit per array task (sbatch --time)")->group("Campaign");
  app->add_option("--cpus-per-task", c.slurm.cpus_per_task, "slurm: CPUs per array task")
      ->check(CLI::Range(1, 4096))->capture_default_str()->group("Campaign");
  app->add_option("--sbatch-opt", c.slurm.sbatch_options, "slurm: extra sbatch option (repeatable), e.g. --sbatch-opt=--qos=long")
      ->allow_extra_args(false)->group("Campaign");
  app->add_option("--chunk", c.slurm.chunk, "slurm: runs per array task")->check(CLI::Range(1, 1000000))
      ->capture_default_str()->group("Campaign");
  app->add_option("--throttle", c.slurm.throttle, "slurm: most array tasks running at once (0 = no limit)")
      ->check(CLI::Range(0, 1000000))->capture_default_str()->group("Campaign");
  app->add_option("--max-retries", c.slurm.max_retries, "slurm: resubmissions of a failed or lost task")
      ->check(CLI::Range(0, 100))->capture_default_str()->group("Campaign");
  app->add_option("--poll", c.slurm.poll_s, "slurm: seconds between squeue queries")
      ->check(CLI::Range(0.01, 3600.0))->capture_default_str()->group("Campaign");
}

// The campaign Options: the YAML file first, then what the command line gave over it. Throws
// config::ConfigError for a refused file, std::invalid_argument for a bad value.
inline Options options(const CliOptions& c, int jobs, bool progress) {
  Options o;
  o.backend = parse_backend(c.backend);
  o.jobs = jobs;
  o.progress = progress;
  o.slurm = c.slurm;
  if (!c.slurm_config.empty()) {
    SlurmOptions file;
    file.dir = c.slurm.dir;
    load_slurm_yaml(c.slurm_config, file);
    auto given = [&](const char* name) { return c.app && c.app->count(name) > 0; };
    if (!given("--campaign-dir")) o.slurm.dir = file.dir;
    if (!given("--partition")) o.slurm.partition = file.partition;
    if (!given("--account")) o.slurm.account = file.account;
    if (!given("--time")) o.slurm.time = file.time;
    if (!given("--cpus-per-task")) o.slurm.cpus_per_task = file.cpus_per_task;
    if (!given("--sbatch-opt")) o.slurm.sbatch_options = file.sbatch_options;
    if (!given("--chunk")) o.slurm.chunk = file.chunk;
    if (!given("--throttle")) o.slurm.throttle = file.throttle;
    if (!given("--max-retries")) o.slurm.max_retries = file.max_retries;
    if (!given("--poll")) o.slurm.poll_s = file.poll_s;
  }
  return o;
}

// True when the command line is the hidden worker entry (`<tool> campaign-worker …`).
inline bool is_worker(int argc, char** argv) {
  return argc >= 2 && std::string_view(argv[1]) == "campaign-worker";
}

}  // namespace pedalwave::campaign::cli
