/* Plant HAL shared by the targets that simulate the motor (host, QEMU): the C plant
 * (firmware_sim/engine/plant.c) is the motor, the amplifier and the encoder. The target's HAL context starts
 * with an hb_plant_hal, so the core's `hal` pointer is one. */
#include "hb_plant_hal.h"

#include <math.h>
#include <string.h>

#include "hb_hal.h"

#define HB_TWO_PI 6.283185307179586

double hb_drift_level(const hb_drift *d) {
    double thermal = 1.0 + d->level_temperature_coefficient * (d->temperature - d->reference_temperature);
    double wear = 1.0 + d->wear_rate * d->distance + (d->distance >= d->wear_step_distance ? d->wear_step : 0.0);
    return thermal > 0.0 ? thermal * wear : 0.0;  /* a law that would turn friction negative stops at zero */
}

double hb_drift_viscous(const hb_drift *d) {
    return exp(-d->viscous_temperature_coefficient * (d->temperature - d->reference_temperature));
}

/* The running parameters from the nominal ones at the drift state: Maxwell-slip stiffnesses (their slip
 * displacements kept, so slip forces scale too), Coulomb and Stribeck levels by L, viscous by b(T)/b_ref. */
static void apply_drift(hb_plant_hal *h) {
    const hb_params *n = &h->nominal;
    hb_params *p = &h->params;
    double level = hb_drift_level(&h->drift), visc = hb_drift_viscous(&h->drift);
    for (int i = 0; i < n->n_elements; i++) h->drift_k[i] = level * n->ms_stiffness[i];
    p->ms_stiffness = h->drift_k;
    p->coulomb_pos = level * n->coulomb_pos;
    p->coulomb_neg = level * n->coulomb_neg;
    p->stribeck_excess = level * n->stribeck_excess;
    p->viscous_pos = visc * n->viscous_pos;
    p->viscous_neg = visc * n->viscous_neg;
    h->drift_left = h->drift_block;
    h->run_cache.valid = 0;  /* new stiffnesses: the Maxwell-slip cache is rebuilt at the next sample */
}

void hb_plant_hal_rest(hb_plant_hal *h, double seconds) {
    hb_drift *d = &h->drift;
    if (!d->on || !(seconds > 0.0)) return;
    d->temperature = d->ambient + (d->temperature - d->ambient) * exp(-seconds / d->thermal_time_constant);
}

hb_real hb_hal_temperature(void *hal) {
    hb_plant_hal *h = hal;
    return h->drift.on ? (hb_real)h->drift.temperature : (hb_real)NAN;
}

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
    h->run_cache.valid = 0;
    if (h->drift.on) {
        h->nominal = h->params;
        h->drift_decay = exp(-h->dt / h->drift.thermal_time_constant);
        long block = lround(h->drift.block / h->dt);
        h->drift_block = block < 1 ? 1 : (int)block;
        apply_drift(h);
    }
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
    double theta_before = h->plant.theta;
    /* one sample per call: the Maxwell-slip cache is carried from sample to sample rather than rebuilt (the O(N)
     * rebuild was half the cost of a sample of the default 16-element plant) */
    if (hb_run_cached(&h->params, &h->plant, &h->run_cache, &u, 1, h->dt, h->substeps, HB_MODE_CURRENT, &out) != 0)
        h->plant_failed = 1;
    if (!h->drift.on) return;
    /* first-order thermal model, exact for the sample's current held (zero-order hold):
     * T+ = T_amb + a*(T - T_amb) + (1 - a)*R_th*R_w*i^2, a = exp(-dt/tau_th); i is the motor's actual current */
    hb_drift *d = &h->drift;
    double i = h->plant.current, a = h->drift_decay;
    d->temperature = d->ambient + a * (d->temperature - d->ambient) +
                     (1.0 - a) * d->thermal_resistance * d->winding_resistance * i * i;
    d->distance += fabs(h->plant.theta - theta_before);  /* the outputs are the sample's start; the state its end */
    if (--h->drift_left <= 0) apply_drift(h);
}
