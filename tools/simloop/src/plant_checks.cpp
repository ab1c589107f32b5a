#include "pedalwave/simloop/plant_checks.hpp"

#include <exception>
#include <sstream>

namespace pedalwave::simloop {

std::string step_problem(const model::IntegratorOptions& integ, double rate_hz, std::string_view period_name) {
  const double period = 1.0 / rate_hz;
  if (model::is_adaptive(integ.method) || integ.h <= period * (1 + 1e-9)) return "";
  std::ostringstream os;
  os << "expected a step ≤ the control period " << period_name << " = " << period << " s";
  return os.str();
}

std::string stability_advice(const model::Scene& scene, const model::ControlGains& gains,
                             const model::IntegratorOptions& integ, double duration) noexcept {
  try {
    const model::StabilityCheck chk = model::check(scene, gains, integ, duration);
    return model::stability_message(chk.report, integ.method, integ.h);
  } catch (const std::exception& e) {
    try {
      return std::string("no stability prediction: ") + e.what();
    } catch (...) {
    }
  } catch (...) {
  }
  return "no stability prediction";
}

}  // namespace pedalwave::simloop
