// model/brdf.c: placeholder while the module is being written.
#include "model/model.h"
