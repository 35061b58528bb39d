// rig/lamps/sim.c — simulated lamps (state only; the virtual rig reads the
// lamps that are on). The wrappers are in rig/lamps/lamps.c.
#include <stdlib.h>

#include "rig/internal.h"

// ---------------------------------------------------------------------------
// Simulated lamps: the state is on_mask, kept by the wrappers.

static int  sim_set(rig_lamps_t *l, uint32_t on_mask) { return RIG_ERR_OK; }
static void sim_close(rig_lamps_t *l) { l->on_mask = 0; }
static void sim_emergency_off(rig_lamps_t *l) { l->on_mask = 0; }

static const rig_lamps_ops_t sim_ops = {
    .backend = "sim",
    .set = sim_set,
    .close = sim_close,
    .emergency_off = sim_emergency_off,
};

int rig_lamps_open_sim(rig_lamps_t **out, const rig_lamp_line_t *lamps, int n)
{
    return rig_lamps_open_sim_state(out, lamps, n, NULL);
}

int rig_lamps_open_sim_state(rig_lamps_t **out, const rig_lamp_line_t *lamps, int n, const char *state_file)
{
    rig_lamps_t *l = NULL;
    int err = rig_lamps_new(out, &l, &sim_ops, lamps, n);
    if (err) return err;
    // Simulated lamps die with the process: a state file only when given one.
    if (state_file && *state_file && (err = rig_lamps_state_open(l, state_file))) {
        rig_lamps_state_close(l, false);
        free(l);
        return err;
    }
    if (!rig_lamps_safety_register(l)) {
        rig_lamps_state_close(l, true);
        free(l);
        return rig_fail(RIG_ERR_NO_MEM, "sim lamps: more than %d lamp sets open at once; close one "
                        "first", RIG_LAMPS_SAFETY_SLOTS);
    }
    *out = l;
    return RIG_ERR_OK;
}
