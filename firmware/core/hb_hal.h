/* The hardware abstraction the core needs. A target implements these functions; `hal` is the target's own
 * context pointer given to hb_device_init (a host process may run several devices).
 *
 * Tick: the target calls hb_device_tick() from its timer (or main loop) with the time in microseconds;
 * received bytes or CAN frames go to hb_device_rx_bytes() / hb_device_rx_can().
 */
#ifndef HB_HAL_H
#define HB_HAL_H

#include <stddef.h>
#include <stdint.h>

#include "hb_config.h"
#include "hb_protocol.h"

/* Apply a new CONFIG: encoder scaling, current output scaling, sample timer. Zero the encoder count.
 * Returns 0, or -1 if the target cannot run this configuration (the device answers INVALID_CONFIG). */
int hb_hal_configure(void *hal, const hb_config *config);

/* Measure sample k at t_k, before its command acts: the encoder count (extended to 64 bits by the target
 * when its counter is narrower) and the motor current, A. */
void hb_hal_measure(void *hal, int64_t *counts, hb_real *current);

/* Drive `current` (A) from t_k to t_k+1; enabled = 0 turns the power stage off (current 0). On a board
 * this writes the DAC and the amplifier's enable pin; the host target advances its plant one sample. */
void hb_hal_apply(void *hal, hb_real current, int enabled);

/* The winding temperature, degC, read when a sample block is sent (protocol v3). A target whose setup
 * declares no HB_SENSOR_TEMPERATURE returns NaN. */
hb_real hb_hal_temperature(void *hal);

/* Serial links: write bytes (a whole frame at a time). CAN links: send one frame. */
void hb_hal_serial_write(void *hal, const uint8_t *data, size_t n);
void hb_hal_can_write(void *hal, uint16_t id, const uint8_t *data, uint8_t len);

#endif
