// A stand-in tool for the campaign tests: its only entry is the array task's worker, with a
// deterministic runner (the result names the specification's hash and length). A specification
// "fail" makes the run throw.
#include <stdexcept>
#include <string>

#include "pedalwave/campaign/campaign.hpp"

namespace campaign = pedalwave::campaign;

std::string fake_runner(const std::string& spec) {
  if (spec == "fail") throw std::runtime_error("this run fails");
  campaign::Record r;
  r.put_text("hash", campaign::hash(spec)).put_int("length", static_cast<long long>(spec.size()));
  return r.line();
}

int main(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) != "campaign-worker") return 2;
  return campaign::worker_main(argc - 1, argv + 1, fake_runner, "fake_tool");
}
