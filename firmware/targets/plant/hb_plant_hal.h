/* The plant behind the HAL: configure, measure and apply on firmware_sim/engine/plant.c. */
#ifndef HB_PLANT_HAL_H
#define HB_PLANT_HAL_H

#include <stdint.h>

#include "plant.h"

typedef struct {
    hb_params base;            /* the simulator's plant; CONFIG supplies current limit, k_t and cpr */
    hb_params params;
    hb_state plant;
    int substeps_by_rate[5];   /* RK4 sub-steps at 1, 2, 5, 10, 20 kHz; 0 = the plant is unstable there */
    uint64_t seed;
    double dt;
    int substeps;
    int plant_failed;          /* the plant state became non-finite */
} hb_plant_hal;

#endif
