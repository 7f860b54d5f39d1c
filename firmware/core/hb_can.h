/* CAN mapping of protocol v1: 11-bit id = type:6 << 5 | direction:1 << 4 | node:4, payloads cut into
 * segments of 7 (classic) or 63 (CAN FD) bytes, each led by `last << 7 | index`; segment 0 starts with
 * the payload length (u16). See docs/protocol.md. */
#ifndef HB_CAN_H
#define HB_CAN_H

#include <stddef.h>
#include <stdint.h>

#include "hb_config.h"

#define HB_CAN_HOST_TO_DEVICE 0
#define HB_CAN_DEVICE_TO_HOST 1
#define HB_CAN_SMALL_PAYLOAD 112     /* largest non-SETPOINTS host message reassembled, bytes (CONFIG v2: 106) */
#define HB_CAN_SETPOINT_PAYLOAD (5 + 4 * HB_MAX_BLOCK)

uint16_t hb_can_id(uint8_t type, uint8_t direction, uint8_t node);

/* Called once per CAN frame of a message being sent. */
typedef void (*hb_can_sink)(void *ctx, uint16_t id, const uint8_t *data, uint8_t len);

/* Cut one message into frames and hand them to `sink`. Returns the number of frames, or 0 when the
 * payload is longer than 128 segments hold. */
int hb_can_send(uint8_t type, const uint8_t *payload, size_t n, uint8_t node, int fd, hb_can_sink sink,
                void *ctx);

typedef struct {
    uint8_t active;           /* a message of this type is being collected */
    uint8_t broken;           /* its current message lost a segment (already counted) */
    uint8_t next;             /* next segment index */
    uint16_t length;          /* payload length from segment 0 */
    uint16_t have;            /* bytes collected */
} hb_can_slot;

/* Reassembles host-to-device messages for one node; statically sized: one buffer per message type of at
 * most HB_CAN_SMALL_PAYLOAD bytes and one for SETPOINTS. */
typedef struct {
    uint8_t node;
    uint32_t dropped_frames;  /* messages lost to missing or out-of-order segments */
    uint32_t errors;          /* complete payloads that were malformed or too long */
    hb_can_slot slots[64];
    uint8_t small[64][HB_CAN_SMALL_PAYLOAD];
    uint8_t setpoints[HB_CAN_SETPOINT_PAYLOAD];
} hb_can_reassembler;

void hb_can_reassembler_init(hb_can_reassembler *r, uint8_t node);
/* Feed one frame. Returns 1 with a complete message (payload valid until the next call), else 0. */
int hb_can_feed(hb_can_reassembler *r, uint16_t id, const uint8_t *data, uint8_t len, uint8_t *type,
                const uint8_t **payload, size_t *n);

#endif
