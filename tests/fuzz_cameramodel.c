// tests/fuzz_cameramodel.c — libFuzzer target over the .cameramodel reader (make fuzz-cameramodel)
//
// The whole input is a .cameramodel text: model_camera_parse checks it and
// only then hands it to mrcal's parser (model/cameramodel.h); a model that
// parses projects a point and unprojects a pixel. Seeds: examples/*.cameramodel
// and the corpus inputs that start with 'c' (the dispatcher's selector, cut off).
#include "tests/fuzz_dispatch.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static bool quiet;
    if (!quiet) {
        model_error_quiet(true);
        quiet = true;
    }
    (void)refl_fuzz_cameramodel((const char *)data, size);
    return 0;
}
