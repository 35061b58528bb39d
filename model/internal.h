// model/internal.h — helpers shared inside model/ (not a public API).
#pragma once

#include <math.h>
#include "model/model.h"

#include "model/vec.h"

// Error with the C source location (for internal failures, not input errors).
#define MODEL_FAIL(...) model_error(__FILE__, __LINE__, __VA_ARGS__)
