// tests/fuzz_parsers.c — libFuzzer target over all text parsers (make fuzz).
// The first input byte selects the parser; see tests/fuzz_dispatch.h.
#include "tests/fuzz_dispatch.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static bool quiet;
    if (!quiet) {
        model_error_quiet(true);
        quiet = true;
    }
    refl_fuzz_one(data, size);
    return 0;
}
