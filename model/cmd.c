// placeholder while the module is being written.
#include <stdio.h>
#include "model/model.h"
int model_cmd_render(int argc, char **argv) { (void)argc; (void)argv; fprintf(stderr, "refl render: unavailable in this build\n"); return 2; }
int model_cmd_edges(int argc, char **argv) { (void)argc; (void)argv; fprintf(stderr, "refl edges: unavailable in this build\n"); return 2; }
