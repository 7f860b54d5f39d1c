/* CAN mapping: segmentation and reassembly (docs/protocol.md, "CAN mapping"). */
#include "hb_can.h"

#include <string.h>

#include "hb_protocol.h"

static const uint8_t fd_lengths[] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64};

uint16_t hb_can_id(uint8_t type, uint8_t direction, uint8_t node) {
    return (uint16_t)((type & 0x3Fu) << 5 | (direction & 1u) << 4 | (node & 0x0Fu));
}

int hb_can_send(uint8_t type, const uint8_t *payload, size_t n, uint8_t node, int fd, hb_can_sink sink,
                void *ctx) {
    const size_t seg = fd ? 63 : 7;
    const size_t body = n + 2;
    if (n > 128 * seg - 2) return 0;
    const size_t count = (body + seg - 1) / seg;
    const uint16_t id = hb_can_id(type, HB_CAN_DEVICE_TO_HOST, node);
    uint8_t frame[64];
    for (size_t i = 0; i < count; i++) {
        size_t start = i * seg, len = body - start < seg ? body - start : seg;
        frame[0] = (uint8_t)((i == count - 1 ? 0x80u : 0u) | i);
        for (size_t j = 0; j < len; j++) {
            size_t b = start + j;  /* byte b of length(u16) | payload */
            frame[1 + j] = b == 0 ? (uint8_t)n : b == 1 ? (uint8_t)(n >> 8) : payload[b - 2];
        }
        size_t size = 1 + len;
        if (fd) {
            size_t k = 0;
            while (fd_lengths[k] < size) k++;
            memset(frame + size, 0, fd_lengths[k] - size);
            size = fd_lengths[k];
        }
        sink(ctx, id, frame, (uint8_t)size);
    }
    return (int)count;
}

void hb_can_reassembler_init(hb_can_reassembler *r, uint8_t node) {
    memset(r->slots, 0, sizeof r->slots);
    r->node = node;
    r->dropped_frames = 0;
    r->errors = 0;
}

static uint8_t *slot_buffer(hb_can_reassembler *r, uint8_t type, size_t *cap) {
    if (type == HB_SETPOINTS) {
        *cap = sizeof r->setpoints;
        return r->setpoints;
    }
    *cap = HB_CAN_SMALL_PAYLOAD;
    return r->small[type];
}

static void append(hb_can_reassembler *r, hb_can_slot *s, uint8_t type, const uint8_t *chunk, size_t len) {
    size_t cap;
    uint8_t *buf = slot_buffer(r, type, &cap);
    size_t room = s->length < cap ? s->length : cap;  /* bytes beyond the length are FD padding */
    for (size_t i = 0; i < len && s->have < room; i++) buf[s->have++] = chunk[i];
}

int hb_can_feed(hb_can_reassembler *r, uint16_t id, const uint8_t *data, uint8_t len, uint8_t *type,
                const uint8_t **payload, size_t *n) {
    uint8_t t = (uint8_t)((id >> 5) & 0x3Fu), dir = (uint8_t)((id >> 4) & 1u), node = (uint8_t)(id & 0x0Fu);
    if (dir != HB_CAN_HOST_TO_DEVICE || node != r->node || len == 0) return 0;
    hb_can_slot *s = &r->slots[t];
    uint8_t index = data[0] & 0x7Fu, last = data[0] & 0x80u;
    if (index == 0) {
        s->broken = 0;
        if (s->active) r->dropped_frames++;  /* a new message started before the previous one ended */
        s->active = 0;
        if (len < 3) {
            r->errors++;
            return 0;
        }
        s->length = hb_get_u16(data + 1);
        s->have = 0;
        s->next = 1;
        s->active = 1;
        append(r, s, t, data + 3, (size_t)len - 3);
    } else {
        if (!s->active || s->next != index) {
            s->active = 0;
            if (!s->broken) {
                r->dropped_frames++;
                s->broken = 1;
            }
            return 0;
        }
        s->next++;
        append(r, s, t, data + 1, (size_t)len - 1);
    }
    if (!last) return 0;
    s->active = 0;
    size_t cap;
    uint8_t *buf = slot_buffer(r, t, &cap);
    if (s->length > cap || s->have < s->length) {
        r->errors++;
        return 0;
    }
    *type = t;
    *payload = buf;
    *n = s->length;
    return 1;
}
