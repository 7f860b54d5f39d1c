/* The device side of protocol v3 (serving v1 and v2 hosts too): configuration, arming, setpoint ring buffer with
 * credit flow control, sample clock, watchdog, limits, latched faults, e-stop, the velocity PI loop and the
 * position PID loop. Static memory only:
 * one hb_device holds every buffer (the target decides where it lives; a board uses one static object).
 * Behaviour: docs/protocol.md; design and float policy: docs/firmware.md.
 */
#ifndef HB_DEVICE_H
#define HB_DEVICE_H

#include <stddef.h>
#include <stdint.h>

#include "hb_can.h"
#include "hb_config.h"
#include "hb_protocol.h"

#define HB_CORE_VERSION "3.0.0"

enum hb_pacing { HB_REALTIME = 0, HB_LOCKSTEP = 1 };
enum hb_link { HB_LINK_SERIAL = 0, HB_LINK_CAN = 1, HB_LINK_CAN_FD = 2 };

typedef struct {
    const char *model, *serial, *firmware;  /* identity strings (kept by the caller) */
    uint32_t capacity;        /* setpoint buffer used, samples, <= HB_BUFFER_CAPACITY */
    uint16_t max_block;       /* <= HB_MAX_BLOCK; 60 on classic CAN */
    uint8_t pacing;           /* enum hb_pacing */
    uint8_t link;             /* enum hb_link */
    uint8_t can_node;         /* 1..15 */
    double velocity_kp;       /* A/(rad/s), velocity PI loop */
    double velocity_ki;       /* A/rad */
    uint8_t sensors;          /* enum hb_sensors: what the board measures beyond the encoder and current */
} hb_device_setup;

typedef struct {
    hb_device_setup setup;
    void *hal;
    uint8_t state;
    uint8_t version;          /* protocol spoken with the host: set by its GET_IDENTITY (1, 2 or 3) */
    hb_config cfg;
    /* derived from the configuration */
    uint32_t window;          /* over-speed window W, samples */
    uint64_t watchdog_us;     /* 0 = off */
    hb_real dt, pos_scale, speed_scale, current_limit, velocity_limit, position_min, position_max;
    uint32_t vps;             /* setpoint values per sample: 2 in position mode with feed-forward, else 1 */
    uint32_t slots;           /* buffer capacity in samples: setup.capacity / vps */
    hb_real d_alpha;          /* pole of the derivative filter, exp(-2*pi*cutoff*dt) (0 = unfiltered) */
    /* latched faults */
    uint16_t faults;
    uint64_t fault_index, fault_silence;
    /* sample clock */
    uint64_t index;           /* next sample index */
    uint64_t t0_us, k0;       /* arrival of the stream's first block and its first sample */
    uint64_t last_rx_us;
    hb_real current_applied;
    /* setpoint ring buffer and credit (head and count in samples; a sample takes vps floats) */
    uint32_t head, count;
    uint32_t expected_seq;
    uint8_t end_seen;
    uint64_t received;
    float ring[HB_BUFFER_CAPACITY];
    /* over-speed history: counts of the last W samples of the stream (circular) */
    int64_t history[HB_MAX_WINDOW];
    uint32_t history_pos;
    uint8_t history_valid;
    /* velocity PI loop */
    hb_real pi_integral, prev_position;
    uint8_t has_prev;
    /* position PID loop: integral term (A), filtered derivative of the error (rad/s), last error (rad) */
    hb_real pos_integral, pos_derivative, prev_error;
    uint8_t has_prev_error;
    /* sample block being assembled */
    uint32_t block_n, sample_seq;
    uint64_t block_first;
    int32_t blk_counts[HB_MAX_BLOCK];
    float blk_cmd[HB_MAX_BLOCK], blk_meas[HB_MAX_BLOCK];
    uint16_t blk_status[HB_MAX_BLOCK];
    /* counters */
    uint32_t crc_errors, dropped_frames, rx_frames, tx_frames, identity_requests;
    /* links */
    hb_frame_decoder decoder;
    hb_can_reassembler can;
    uint8_t tx[HB_COBS_MAX(HB_MAX_FRAME)];
    uint8_t payload[HB_SAMPLES_HEADER_BYTES_V3 + HB_SAMPLE_BYTES * HB_MAX_BLOCK];
} hb_device;

void hb_device_init(hb_device *d, const hb_device_setup *setup, void *hal);
/* Bytes from a serial link, received at now_us. */
void hb_device_rx_bytes(hb_device *d, const uint8_t *data, size_t n, uint64_t now_us);
/* One CAN frame, received at now_us. */
void hb_device_rx_can(hb_device *d, uint16_t id, const uint8_t *data, uint8_t len, uint64_t now_us);
/* One decoded message (type and payload), received at now_us. */
void hb_device_handle(hb_device *d, uint8_t type, const uint8_t *payload, size_t n, uint64_t now_us);
/* Run the sample clock up to now_us: compute the samples due, check the watchdog, send the blocks. */
void hb_device_tick(hb_device *d, uint64_t now_us);
/* Lockstep pacing has samples it could compute right now. */
int hb_device_busy(const hb_device *d);
void hb_device_status(const hb_device *d, uint32_t token, hb_status *s);
/* Frames the link lost outside the core (a host that does not read): counted as dropped. */
void hb_device_count_dropped(hb_device *d, uint32_t frames);

#endif
