/* Host target: the firmware core with the C plant (firmware_sim/plant.c) behind its HAL, driven from
 * Python through cffi (hilbench.firmware_sim.core_c). Output bytes and CAN frames are queued here for the
 * Python transport to send. */
#ifndef HB_HOST_H
#define HB_HOST_H

#include <stddef.h>
#include <stdint.h>

#include "hb_device.h"
#include "plant.h"

#define HB_HOST_TX_BYTES (1 << 20)
#define HB_HOST_CAN_FRAMES 32768

typedef struct {
    uint16_t id;
    uint8_t len;
    uint8_t data[64];
} hb_host_can_frame;

typedef struct {
    hb_params base;            /* the simulator's plant; CONFIG supplies current limit, k_t and cpr */
    hb_params params;
    hb_state plant;
    int substeps_by_rate[5];   /* RK4 sub-steps at 1, 2, 5, 10, 20 kHz; 0 = the plant is unstable there */
    uint64_t seed;
    double dt;
    int substeps;
    int plant_failed;          /* the plant state became non-finite */
    size_t tx_len;
    uint32_t tx_dropped;       /* frames that did not fit the queue */
    uint32_t can_n;
    hb_device device;
    uint8_t tx[HB_HOST_TX_BYTES];
    hb_host_can_frame can[HB_HOST_CAN_FRAMES];
} hb_host;

/* base, substeps_by_rate and seed are set by the caller first. */
void hb_host_init(hb_host *h, const hb_device_setup *setup);

#endif
