// The command-line policy every pedalwave tool shares (README "Bad input and exit codes"), written
// once: a refused command line or option value is ONE line on stderr, "<tool>: error: <what>", and
// exit status 2 — never CLI11's own codes (104 … 114) — with --help still exiting 0. The exit
// statuses below mean the same in every tool.
//
// Header-only on purpose: the toolkit library stays free of CLI11; a tool links pedalwave::cli.
#pragma once

#include <CLI/CLI.hpp>

#include <cmath>
#include <exception>
#include <iostream>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>

#include "pedalwave/config/yaml_reader.hpp"  // config::ConfigError: a refused file is bad input

namespace pedalwave::toolkit::cli {

inline constexpr int kExitOk = 0;             // done; a daemon: duration reached or SIGTERM/SIGINT/SIGHUP/SIGQUIT
inline constexpr int kExitInternal = 1;       // an error that is not the input's (cannot write a file, …)
inline constexpr int kExitBadInput = 2;       // the command line or a file was refused (one line)
inline constexpr int kExitNumerical = 3;      // a simulation went numerically wrong (NaN, singular)
inline constexpr int kExitFault = 4;          // a fault ended the run (safe stop)
inline constexpr int kExitEmergencyStop = 5;  // an operator emergency stop ended the run

// "<tool>: error: <what>" on stderr; returns kExitBadInput.
inline int bad_input(std::string_view tool, const std::string& what) {
  std::cerr << tool << ": error: " << what << '\n';
  return kExitBadInput;
}

// The exit status of the exception being handled (call it inside a catch block), with its one
// line "<tool>: error: <what>" on stderr: a file the configuration reader refused
// (config::ConfigError: file:line, key, value, what was expected) and a value refused by a check
// (std::invalid_argument) are bad input, kExitBadInput; anything else is kExitInternal.
inline int exit_for_current_exception(std::string_view tool) {
  try {
    throw;
  } catch (const config::ConfigError& e) {
    return bad_input(tool, e.what());
  } catch (const std::invalid_argument& e) {
    return bad_input(tool, e.what());
  } catch (const std::exception& e) {
    std::cerr << tool << ": error: " << e.what() << '\n';
  } catch (...) {
    std::cerr << tool << ": error: unknown exception\n";
  }
  return kExitInternal;
}

// Runs a tool's work, body() → its exit status, mapping what escapes it as above: no bad input
// leaves a tool as exit 1.
template <class Body>
int run(std::string_view tool, Body&& body) {
  try {
    return body();
  } catch (...) {
    return exit_for_current_exception(tool);
  }
}

// How a run of the runtime ended (runtime::ExitReason, by the name the exit line and the JSON
// report use: "cycle_limit", "stop_requested", "signal", "fault", "emergency_stop") → the exit
// status: the daemon's (app::exit_code) and every tool that drives it (pedalwave_soak).
// kExitInternal for "none" or an unknown name (the run did not end in order).
inline int exit_for_run_end(std::string_view reason) {
  if (reason == "cycle_limit" || reason == "stop_requested" || reason == "signal") return kExitOk;
  if (reason == "fault") return kExitFault;
  if (reason == "emergency_stop") return kExitEmergencyStop;
  return kExitInternal;
}

// Parses the command line. nullopt: go on. Otherwise the exit status to return: 0 after --help
// (printed), kExitBadInput after one error line. An unknown word where a subcommand is required
// is named ("'dance' is not a subcommand: expected one of flat, friction, …"), not CLI11's "A
// subcommand is required".
inline std::optional<int> parse(CLI::App& app, int argc, char** argv, std::string_view tool) {
  try {
    app.parse(argc, argv);
    return std::nullopt;
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);  // --help, --help-all, --version
    const auto subs = app.get_subcommands([](CLI::App*) { return true; });
    if (!subs.empty() && app.get_subcommands().empty()) {
      for (int i = 1; i < argc; ++i) {
        const std::string word = argv[i];
        if (word.empty() || word[0] == '-') continue;
        std::string names;
        for (const CLI::App* s : subs) names += (names.empty() ? "" : ", ") + s->get_name();
        return bad_input(tool, "'" + word + "' is not a subcommand: expected one of " + names + " (see --help)");
      }
    }
    std::string what = e.what();
    for (char& c : what)
      if (c == '\n') c = ' ';
    return bad_input(tool, what + " (see --help)");
  }
}

// Option validators with short messages (CLI::PositiveNumber prints the whole double range and
// lets nan and inf through to some options): a finite number > 0, and a finite number in [lo, hi].
inline CLI::Validator finite_positive() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        try {
          std::size_t used = 0;
          const double v = std::stod(text, &used);
          if (used == text.size() && std::isfinite(v) && v > 0) return {};
        } catch (const std::exception&) {
        }
        return "'" + text + "': expected a finite number > 0";
      },
      "> 0", "finite_positive");
}
inline CLI::Validator finite_in(double lo, double hi) {
  std::ostringstream range;
  range << "[" << lo << ", " << hi << "]";
  return CLI::Validator(
      [lo, hi](std::string& text) -> std::string {
        try {
          std::size_t used = 0;
          const double v = std::stod(text, &used);
          if (used == text.size() && std::isfinite(v) && v >= lo && v <= hi) return {};
        } catch (const std::exception&) {
        }
        std::ostringstream os;
        os << "'" << text << "': expected a finite number in [" << lo << ", " << hi << "]";
        return os.str();
      },
      range.str(), "finite_in");
}

}  // namespace pedalwave::toolkit::cli
