/* A scripted HAL for the core's unit tests: the encoder reads a script (or holds), the measured current
 * is the last applied command times `gain`, and every write is captured. With `inertia` > 0 the encoder
 * reads a pure inertia instead: J*theta'' = kt*i, the current held over each sample period `dt` (exact
 * zero-order-hold integration), theta quantised to `cpr` counts per revolution. */
#ifndef FAKE_HAL_H
#define FAKE_HAL_H

#include <stddef.h>
#include <stdint.h>

#include "hb_device.h"

#define FAKE_TX (1 << 20)
#define FAKE_SCRIPT 8192

typedef struct {
    int64_t script[FAKE_SCRIPT];  /* counts of sample k (holds the last entry beyond n_script) */
    size_t n_script;
    size_t measured;              /* samples measured (the index into the script) */
    double gain;                  /* measured current = gain * last applied current, A */
    double applied;               /* last applied current, A */
    int enabled;
    int configured;
    double inertia, kt, dt, cpr;  /* pure-inertia encoder: kg*m^2, N*m/A, s, counts/rev (0 = script) */
    double theta, omega;          /* rad, rad/s */
    double temperature;           /* degC read at sample 0; the reading grows 0.25 degC per sample measured */
    size_t temperature_reads;
    size_t tx_len;
    uint8_t tx[FAKE_TX];
    uint32_t can_frames;
    uint16_t can_id[4096];
    uint8_t can_len[4096];
    uint8_t can_data[4096][64];
} fake_hal;

#endif
