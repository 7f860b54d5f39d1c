/* Host target: the firmware core with the C plant (firmware_sim/engine/plant.c) behind its HAL, driven from
 * Python through cffi (hilbench.firmware_sim.devices.core_c). Output bytes and CAN frames are queued here for the
 * Python transport to send. */
#ifndef HB_HOST_H
#define HB_HOST_H

#include <stddef.h>
#include <stdint.h>

#include "hb_device.h"
#include "hb_plant_hal.h"

#define HB_HOST_TX_BYTES (1 << 20)
#define HB_HOST_CAN_FRAMES 32768

typedef struct {
    uint16_t id;
    uint8_t len;
    uint8_t data[64];
} hb_host_can_frame;

typedef struct {
    hb_plant_hal sim;          /* first: the core's hal pointer is also the plant HAL's */
    size_t tx_len;
    uint32_t tx_dropped;       /* frames that did not fit the queue */
    uint32_t can_n;
    hb_device device;
    uint8_t tx[HB_HOST_TX_BYTES];
    hb_host_can_frame can[HB_HOST_CAN_FRAMES];
} hb_host;

/* sim.base, sim.substeps_by_rate and sim.seed are set by the caller first. */
void hb_host_init(hb_host *h, const hb_device_setup *setup);

#endif
