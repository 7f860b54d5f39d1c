/* Plant HAL shared by the targets that simulate the motor (host, QEMU): the C plant
 * (firmware_sim/engine/plant.c) is the motor, the amplifier and the encoder. The target's HAL context starts
 * with an hb_plant_hal, so the core's `hal` pointer is one. */
#include "hb_plant_hal.h"

#include <math.h>
#include <string.h>

#include "hb_hal.h"

#define HB_TWO_PI 6.283185307179586

int hb_hal_configure(void *hal, const hb_config *c) {
    hb_plant_hal *h = hal;
    static const uint32_t rates[5] = {1000, 2000, 5000, 10000, 20000};
    int substeps = 0;
    for (int i = 0; i < 5; i++)
        if (rates[i] == c->sample_rate) substeps = h->substeps_by_rate[i];
    if (substeps < 1) return -1;
    h->params = h->base;
    h->params.current_limit = c->current_limit;
    h->params.torque_constant = c->torque_constant;
    h->params.counts_per_rev = (int64_t)c->counts_per_rev;
    h->dt = 1.0 / (double)c->sample_rate;
    h->substeps = substeps;
    hb_state_init(&h->plant, &h->params, 0.0, 0.0, h->seed);
    return 0;
}

/* The plant measures inside hb_run, together with the step; the HAL must measure first (the core checks
 * limits and closes its velocity loop on the measurement). So it repeats the plant's measurement on a
 * copy of the generator state: the same deviates are drawn again by the hb_run that follows, and the
 * counts and current are the plant's own, bit for bit (docs/plant.md, "sampling"). */
void hb_hal_measure(void *hal, int64_t *counts, hb_real *current) {
    hb_plant_hal *h = hal;
    hb_state *s = &h->plant;
    const hb_params *p = &h->params;
    uint64_t rng[4];
    memcpy(rng, s->rng, sizeof rng);
    double spare = s->spare_normal;
    int32_t has_spare = s->has_spare;
    double i_meas = s->current, th_noisy = s->theta, z;
    if (p->noise_current > 0.0) {
        hb_normals(s, &z, 1);
        i_meas += p->noise_current * z;
    }
    if (p->noise_position > 0.0) {
        hb_normals(s, &z, 1);
        th_noisy += p->noise_position * z;
    }
    memcpy(s->rng, rng, sizeof rng);
    s->spare_normal = spare;
    s->has_spare = has_spare;
    if (p->counts_per_rev > 0) {
        double cpr = (double)p->counts_per_rev;
        *counts = (int64_t)floor(th_noisy * cpr / HB_TWO_PI + 0.5);
    } else {
        *counts = 0;
    }
    *current = (hb_real)i_meas;
}

void hb_hal_apply(void *hal, hb_real current, int enabled) {
    hb_plant_hal *h = hal;
    double u = enabled ? (double)current : 0.0;
    double theta, omega, friction, cmd, meas, torque, pos;
    int64_t counts;
    hb_outputs out = {&theta, &omega, &friction, &cmd, &meas, &torque, &pos, &counts};
    if (hb_run(&h->params, &h->plant, &u, 1, h->dt, h->substeps, HB_MODE_CURRENT, &out) != 0) h->plant_failed = 1;
}
