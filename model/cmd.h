// model/cmd.h — the model layer's commands: refl render, edges, workpiece and brdf
//
// Part of model/model.h, whose conventions (units, frames, pixel coordinates,
// errors, model_*_free(NULL)) apply here.
#pragma once

#ifdef __cplusplus
extern "C" {
#endif

// ---------------------------------------------------------------------------
// Commands (model/cmd.c): argv[0] is the subcommand name. Return the exit code.
int model_cmd_render(int argc, char **argv);
int model_cmd_edges(int argc, char **argv);
int model_cmd_workpiece(int argc, char **argv);
int model_cmd_brdf(int argc, char **argv);   // refl brdf tabulate (model/cmd_brdf.c)

#ifdef __cplusplus
}
#endif
