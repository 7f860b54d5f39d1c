#include "fake_hal.h"

#include <math.h>
#include <string.h>

#include "hb_hal.h"

int hb_hal_configure(void *hal, const hb_config *config) {
    fake_hal *f = hal;
    (void)config;
    f->configured++;
    f->measured = 0;
    return 0;
}

void hb_hal_measure(void *hal, int64_t *counts, hb_real *current) {
    fake_hal *f = hal;
    size_t k = f->measured < f->n_script ? f->measured : (f->n_script ? f->n_script - 1 : 0);
    *counts = f->n_script ? f->script[k] : 0;
    if (f->inertia > 0) *counts = (int64_t)floor(f->theta * f->cpr / 6.283185307179586 + 0.5);
    *current = (hb_real)(f->gain * f->applied);
}

void hb_hal_apply(void *hal, hb_real current, int enabled) {
    fake_hal *f = hal;
    f->applied = enabled ? (double)current : 0.0;
    f->enabled = enabled;
    if (f->inertia > 0) {
        double acc = f->kt * f->applied / f->inertia;
        f->theta += f->omega * f->dt + 0.5 * acc * f->dt * f->dt;
        f->omega += acc * f->dt;
    }
    f->measured++;
}

hb_real hb_hal_temperature(void *hal) {
    fake_hal *f = hal;
    f->temperature_reads++;
    return (hb_real)(f->temperature + 0.25 * (double)f->measured);  /* distinct per block: which sample read it */
}

void hb_hal_serial_write(void *hal, const uint8_t *data, size_t n) {
    fake_hal *f = hal;
    if (f->tx_len + n <= FAKE_TX) {
        memcpy(f->tx + f->tx_len, data, n);
        f->tx_len += n;
    }
}

void hb_hal_can_write(void *hal, uint16_t id, const uint8_t *data, uint8_t len) {
    fake_hal *f = hal;
    if (f->can_frames < 4096) {
        f->can_id[f->can_frames] = id;
        f->can_len[f->can_frames] = len;
        memcpy(f->can_data[f->can_frames], data, len);
        f->can_frames++;
    }
}
