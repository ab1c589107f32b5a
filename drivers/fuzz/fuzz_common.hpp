// Helpers of the libFuzzer targets: a failed property is a crash (abort), which libFuzzer reports.
#pragma once

#include <cstdio>
#include <cstdlib>

#define PW_FUZZ_CHECK(cond)                                                 \
  do {                                                                      \
    if (!(cond)) {                                                          \
      std::fprintf(stderr, "fuzz property failed: %s (%s:%d)\n", #cond,     \
                   __FILE__, __LINE__);                                     \
      std::abort();                                                         \
    }                                                                       \
  } while (0)
