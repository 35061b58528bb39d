// tests/fuzz_cameramodel.c — libFuzzer target over the .cameramodel reader (make fuzz-cameramodel)
//
// The whole input is a .cameramodel text: model_camera_parse checks it and
// only then hands it to mrcal's parser (model/cameramodel.h); a model that
// parses projects a point and unprojects a pixel. A text the check passes
// that mrcal's parser then refuses is a finding too (abort): the check must
// accept only what mrcal reads. Seeds: examples/*.cameramodel and the corpus
// inputs that start with 'c' (the dispatcher's selector, cut off).
#include "model/cameramodel.h"
#include "tests/fuzz_dispatch.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static bool quiet;
    if (!quiet) {
        model_error_quiet(true);
        quiet = true;
    }
    const char *text = (const char *)data;
    if (model_cameramodel_check(text, size, "fuzz.cameramodel")) {
        mrcal_cameramodel_t *m = model_cameramodel_parse(text, size, "fuzz.cameramodel");
        if (!m) abort();   // the check passed what mrcal refuses
        mrcal_free_cameramodel(&m);
    }
    (void)refl_fuzz_cameramodel(text, size);
    return 0;
}
