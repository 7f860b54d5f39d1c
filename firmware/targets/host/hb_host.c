/* Host HAL: the plant (hb_plant_hal.c) and output queues for the Python transport. */
#include "hb_host.h"

#include <string.h>

#include "hb_hal.h"

void hb_host_init(hb_host *h, const hb_device_setup *setup) {
    h->tx_len = 0;
    h->tx_dropped = 0;
    h->can_n = 0;
    h->sim.plant_failed = 0;
    hb_device_init(&h->device, setup, h);
}

void hb_hal_serial_write(void *hal, const uint8_t *data, size_t n) {
    hb_host *h = hal;
    if (h->tx_len + n > sizeof h->tx) {
        h->tx_dropped++;
        return;
    }
    memcpy(h->tx + h->tx_len, data, n);
    h->tx_len += n;
}

void hb_hal_can_write(void *hal, uint16_t id, const uint8_t *data, uint8_t len) {
    hb_host *h = hal;
    if (h->can_n >= HB_HOST_CAN_FRAMES) {
        h->tx_dropped++;
        return;
    }
    hb_host_can_frame *f = &h->can[h->can_n++];
    f->id = id;
    f->len = len;
    memcpy(f->data, data, len);
}
