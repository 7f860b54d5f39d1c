/* The plant behind the HAL: configure, measure and apply on firmware_sim/engine/plant.c. */
#ifndef HB_PLANT_HAL_H
#define HB_PLANT_HAL_H

#include <stdint.h>

#include "plant.h"

/* Slow drift of the simulated motor (docs/campaign-analysis.md, "Drift physics"); on = 0 leaves the plant
 * as configured and the device reports no temperature. Temperatures in degC. */
typedef struct {
    int on;
    double winding_resistance;        /* R_w, ohm */
    double thermal_resistance;        /* R_th, K/W, winding to ambient */
    double thermal_time_constant;     /* tau_th, s */
    double reference_temperature;     /* T_ref: the plant's parameters hold at T_ref and distance 0 */
    double level_temperature_coefficient;   /* alpha, 1/K */
    double viscous_temperature_coefficient; /* beta, 1/K */
    double wear_rate;                 /* w, relative friction level increase per rad slid */
    double wear_step;                 /* relative level step at wear_step_distance */
    double wear_step_distance;        /* rad (+inf: none) */
    double block;                     /* s between updates of the friction parameters */
    /* state, carried across CONFIGs: the motor keeps its heat and its wear */
    double ambient;                   /* degC */
    double temperature;               /* winding, degC */
    double distance;                  /* sliding distance since the device started, rad */
} hb_drift;

typedef struct {
    hb_params base;            /* the simulator's plant; CONFIG supplies current limit, k_t and cpr */
    hb_params params;
    hb_state plant;
    int substeps_by_rate[5];   /* RK4 sub-steps at 1, 2, 5, 10, 20 kHz; 0 = the plant is unstable there */
    uint64_t seed;
    double dt;
    int substeps;
    int plant_failed;          /* the plant state became non-finite */
    hb_run_cache run_cache;    /* hb_run's set-up kept between samples; invalid after CONFIG and each drift update */
    hb_drift drift;
    hb_params nominal;         /* base + CONFIG, before the drift laws */
    double drift_decay;        /* exp(-dt/tau_th) */
    int drift_block, drift_left; /* samples per parameter update, and until the next one */
    double drift_k[HB_MAX_ELEMENTS]; /* the drifted Maxwell-slip stiffnesses (params.ms_stiffness points here) */
} hb_plant_hal;

/* Let the winding cool towards ambient for `seconds` with no current (between runs). */
void hb_plant_hal_rest(hb_plant_hal *h, double seconds);
/* Friction level L(T, s) and viscous factor b(T)/b_ref of the drift laws at the present state. */
double hb_drift_level(const hb_drift *d);
double hb_drift_viscous(const hb_drift *d);

#endif
