// Everything of pedalwave::toolkit in one include.
#pragma once

#include "pedalwave/toolkit/color.hpp"
#include "pedalwave/toolkit/cpu_load.hpp"
#include "pedalwave/toolkit/csv.hpp"
#include "pedalwave/toolkit/figure.hpp"
#include "pedalwave/toolkit/json.hpp"
#include "pedalwave/toolkit/plots.hpp"
#include "pedalwave/toolkit/progress.hpp"
#include "pedalwave/toolkit/table.hpp"
#include "pedalwave/toolkit/ticks.hpp"
