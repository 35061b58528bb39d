// tests/fuzz_parsers.c — libFuzzer target over all text parsers (make fuzz):
// the model's scene and INI files, and the rig's capture plans, rig files and
// virtual-rig truth files. The first input byte selects the parser; see
// tests/fuzz_dispatch.h. Truth files resolve their camera model and scenes in
// the repo's examples/ (compiled in by make fuzz; $REFL_FUZZ_EXAMPLES overrides).
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
