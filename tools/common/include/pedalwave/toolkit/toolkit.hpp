// Everything of pedalwave::toolkit in one include.
#pragma once

#include "pedalwave/toolkit/body_csv.hpp"
#include "pedalwave/toolkit/cpu_load.hpp"
#include "pedalwave/toolkit/csv.hpp"
#include "pedalwave/toolkit/figures.hpp"
#include "pedalwave/toolkit/json.hpp"
#include "pedalwave/toolkit/progress.hpp"
#include "pedalwave/toolkit/table.hpp"
