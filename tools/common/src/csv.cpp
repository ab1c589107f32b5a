#include "pedalwave/toolkit/csv.hpp"

#include "pedalwave/toolkit/format.hpp"

namespace pedalwave::toolkit {

std::string format_double(double v) { return exact(v); }

}  // namespace pedalwave::toolkit
