// The tools' CSV: the project's one writer and reader (pedalwave::csv, common/csv), under the
// toolkit's names. Numeric data files for recordings and study results: optional '#' comment
// lines, one header line, rows of numbers written as the shortest text that reads back to the
// same double (std::to_chars; "nan", "inf", "-inf"), so a write/read round trip is exact.
#pragma once

#include <string>

#include "pedalwave/csv/csv.hpp"

namespace pedalwave::toolkit {

// Shortest round-trip text of a double ("0.1", "1e-300", "nan", "-inf"), as CsvWriter writes it.
[[nodiscard]] std::string format_double(double v);

using CsvError = csv::Error;
using CsvWriter = csv::Writer;
using CsvTable = csv::Table;

}  // namespace pedalwave::toolkit
