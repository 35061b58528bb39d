// tests/test_corpus.c: placeholder while the module is being written.
#include "model/model.h"
