/* Device state machine of protocol v3, serving v1 and v2 hosts too (docs/protocol.md; design: docs/firmware.md). */
#include "hb_device.h"

#include <math.h>
#include <string.h>

#include "hb_hal.h"

#define HB_TWO_PI 6.283185307179586
#define US_PER_S 1000000u

/* ------------------------------------------------------------------ output */

static void send_can_frame(void *ctx, uint16_t id, const uint8_t *data, uint8_t len) {
    hb_device *d = ctx;
    hb_hal_can_write(d->hal, id, data, len);
}

static void send(hb_device *d, uint8_t type, const uint8_t *payload, size_t n) {
    if (d->setup.link == HB_LINK_SERIAL) {
        size_t len = hb_frame_encode_version(d->version, type, payload, n, d->tx);
        if (!len) {
            d->dropped_frames++;
            return;
        }
        hb_hal_serial_write(d->hal, d->tx, len);
    } else if (!hb_can_send(type, payload, n, d->setup.can_node, d->setup.link == HB_LINK_CAN_FD,
                            send_can_frame, d)) {
        d->dropped_frames++;
        return;
    }
    d->tx_frames++;
}

static uint32_t free_slots(const hb_device *d) { return d->slots - d->count; }

void hb_device_status(const hb_device *d, uint32_t token, hb_status *s) {
    s->token = token;
    s->state = d->state;
    s->faults = d->faults;
    s->index = d->index;
    s->free = free_slots(d);
    s->received = d->received;
    s->fault_index = d->fault_index;
    s->fault_silence = d->fault_silence;
    s->current_applied = (float)d->current_applied;
    s->crc_errors = d->crc_errors + d->decoder.crc_errors + d->can.errors;
    s->dropped_frames = d->dropped_frames + d->can.dropped_frames;
    s->rx_frames = d->rx_frames;
    s->tx_frames = d->tx_frames;
}

static void send_status(hb_device *d, uint32_t token) {
    hb_status s;
    hb_device_status(d, token, &s);
    hb_status_encode(&s, d->payload);
    send(d, HB_STATUS, d->payload, HB_STATUS_BYTES);
}

static void send_reply(hb_device *d, uint8_t request, uint8_t result, uint16_t faults) {
    uint8_t out[4];
    hb_reply_encode(request, result, faults, out);
    send(d, HB_REPLY, out, sizeof out);
}

/* Send the samples collected so far as one SAMPLES block (header: state and credit as they are now). */
static void flush_block(hb_device *d) {
    uint32_t n = d->block_n;
    if (!n) return;
    hb_samples_header h = {d->sample_seq++, free_slots(d), d->block_first, d->received, d->faults, d->state,
                           (d->setup.sensors & HB_SENSOR_TEMPERATURE) ? (float)hb_hal_temperature(d->hal) : NAN};
    uint8_t *p = d->payload;
    size_t head = hb_samples_header_encode_version(&h, d->version, p);
    p += head;
    for (uint32_t i = 0; i < n; i++) hb_put_u32(p + 4 * i, (uint32_t)d->blk_counts[i]);
    for (uint32_t i = 0; i < n; i++) hb_put_f32(p + 4 * (n + i), d->blk_cmd[i]);
    for (uint32_t i = 0; i < n; i++) hb_put_f32(p + 4 * (2 * n + i), d->blk_meas[i]);
    for (uint32_t i = 0; i < n; i++) hb_put_u16(p + 12 * n + 2 * i, d->blk_status[i]);
    d->block_n = 0;
    send(d, HB_SAMPLES, d->payload, head + (size_t)HB_SAMPLE_BYTES * n);
}

/* ------------------------------------------------------------------ state */

void hb_device_init(hb_device *d, const hb_device_setup *setup, void *hal) {
    memset(d, 0, sizeof *d);
    d->setup = *setup;
    if (d->setup.capacity == 0 || d->setup.capacity > HB_BUFFER_CAPACITY) d->setup.capacity = HB_BUFFER_CAPACITY;
    if (d->setup.max_block == 0 || d->setup.max_block > HB_MAX_BLOCK) d->setup.max_block = HB_MAX_BLOCK;
    d->hal = hal;
    d->state = HB_UNCONFIGURED;
    d->version = HB_PROTOCOL_VERSION;
    d->vps = 1;
    d->slots = d->setup.capacity;
    hb_frame_decoder_init(&d->decoder);
    hb_can_reassembler_init(&d->can, setup->can_node);
}

static void latch(hb_device *d, uint16_t faults, uint64_t index, uint64_t silence) {
    if (!d->faults) {
        d->fault_index = index;
        d->fault_silence = silence;
    }
    d->faults |= faults;
}

static void reset_stream(hb_device *d) {
    d->head = d->count = 0;
    d->end_seen = 0;
    d->expected_seq = 0;
    d->received = 0;
    d->history_valid = 0;
    d->pi_integral = 0;  /* each stream starts its velocity loop without a stale integral */
    d->pos_integral = 0;  /* and its position loop without a stale integral or derivative */
    d->pos_derivative = 0;
    d->has_prev_error = 0;
}

int hb_device_busy(const hb_device *d) { return d->state == HB_STREAMING && d->count > 0; }

void hb_device_count_dropped(hb_device *d, uint32_t frames) { d->dropped_frames += frames; }

/* ------------------------------------------------------------------ samples */

/* Over-speed estimate v[k] = 2*pi/cpr * (counts[k] - counts[k-W]) / (W*dt); before the stream's first
 * sample the motor is taken at rest at that sample's count. */
static hb_real speed(hb_device *d, int64_t counts) {
    if (!d->history_valid) {
        for (uint32_t i = 0; i < d->window; i++) d->history[i] = counts;
        d->history_pos = 0;
        d->history_valid = 1;
    }
    return (hb_real)(counts - d->history[d->history_pos]) * d->speed_scale;
}

static void remember(hb_device *d, int64_t counts) {
    d->history[d->history_pos] = counts;
    d->history_pos = (d->history_pos + 1) % d->window;
}

/* `current_setpoint` is the streamed current (current mode) or feed-forward current (position mode), A. */
static uint16_t limit_trips(hb_device *d, int64_t counts, hb_real meas, hb_real current_setpoint) {
    uint16_t bits = 0;
    if (fabs(meas) > d->current_limit || fabs(current_setpoint) > d->current_limit) bits |= HB_F_OVER_CURRENT;
    if (fabs(speed(d, counts)) > d->velocity_limit) bits |= HB_F_OVER_SPEED;
    hb_real position = (hb_real)counts * d->pos_scale;
    if (position < d->position_min || position > d->position_max) bits |= HB_F_POSITION_WINDOW;
    return bits;
}

/* Velocity PI loop on the encoder: v = (pos[k] - pos[k-1]) / dt; the integral is only updated while the
 * output is not saturated or when the error drives it out of saturation (anti-windup). */
static hb_real velocity_loop(hb_device *d, hb_real setpoint, hb_real position) {
    hb_real v_est = d->has_prev ? (position - d->prev_position) / d->dt : (hb_real)0;
    hb_real err = setpoint - v_est;
    hb_real integral = d->pi_integral + err * d->dt;
    hb_real i_cmd = (hb_real)d->setup.velocity_kp * err + (hb_real)d->setup.velocity_ki * integral;
    hb_real lim = d->current_limit;
    if (i_cmd > lim) {
        i_cmd = lim;
        if (err < 0) d->pi_integral = integral;
    } else if (i_cmd < -lim) {
        i_cmd = -lim;
        if (err > 0) d->pi_integral = integral;
    } else {
        d->pi_integral = integral;
    }
    return i_cmd;
}

static hb_real clip(hb_real v, hb_real lim) { return v > lim ? lim : v < -lim ? -lim : v; }

/* Position PID loop on the encoder: e = r - pos; D = a*D + (1 - a)*(e[k] - e[k-1])/dt (0 on a stream's
 * first sample); I = clip(I + ki*e*dt, i_limit); i = clip(kp*e + kd*D + I + ff, current_limit). The
 * integral is not advanced while the output is saturated and the error drives it further (anti-windup). */
static hb_real position_loop(hb_device *d, hb_real setpoint, hb_real ff, hb_real position) {
    const hb_config *c = &d->cfg;
    hb_real err = setpoint - position;
    hb_real raw = d->has_prev_error ? (err - d->prev_error) / d->dt : (hb_real)0;
    d->pos_derivative = d->d_alpha * d->pos_derivative + ((hb_real)1 - d->d_alpha) * raw;
    d->prev_error = err;
    d->has_prev_error = 1;
    hb_real integral = clip(d->pos_integral + (hb_real)c->position_ki * err * d->dt, (hb_real)c->position_i_limit);
    hb_real i_cmd = (hb_real)c->position_kp * err + (hb_real)c->position_kd * d->pos_derivative + integral + ff;
    hb_real lim = d->current_limit;
    if ((i_cmd > lim && err > 0) || (i_cmd < -lim && err < 0)) {
        i_cmd = (hb_real)c->position_kp * err + (hb_real)c->position_kd * d->pos_derivative + d->pos_integral + ff;
    } else {
        d->pos_integral = integral;
    }
    return clip(i_cmd, lim);
}

/* Append sample `index` to the block; a full block goes out only when the next sample arrives, so that
 * the end of a stream can still mark its last sample. */
static void record(hb_device *d, int64_t counts, hb_real cmd, hb_real meas, uint16_t status) {
    if (d->block_n == d->setup.max_block) flush_block(d);
    if (!d->block_n) d->block_first = d->index;
    uint32_t i = d->block_n++;
    d->blk_counts[i] = (int32_t)(uint32_t)(uint64_t)counts;  /* counts modulo 2^32 on the wire */
    d->blk_cmd[i] = (float)cmd;
    d->blk_meas[i] = (float)meas;
    d->blk_status[i] = status;
    d->index++;
    d->current_applied = cmd;
}

static hb_real encoder_position(const hb_device *d, int64_t counts) {
    return (hb_real)((double)counts * HB_TWO_PI / (double)d->cfg.counts_per_rev);
}

/* Sample k (already measured) with the power stage off; it ends the stream: END (| FAULT), DISARMED,
 * `faults` latched at k with the host's silence then. */
static void end_sample(hb_device *d, int64_t counts, hb_real meas, uint16_t faults, uint64_t silence) {
    if (faults) latch(d, faults, d->index, silence);
    hb_hal_apply(d->hal, 0, 0);
    d->prev_position = encoder_position(d, counts);
    d->has_prev = 1;
    record(d, counts, 0, meas, (uint16_t)(HB_S_END | (faults ? HB_S_FAULT : 0)));
    d->state = HB_DISARMED;
    reset_stream(d);
    flush_block(d);
}

static void end_stream_with(hb_device *d, uint16_t faults, uint64_t silence) {
    int64_t counts;
    hb_real meas;
    hb_hal_measure(d->hal, &counts, &meas);
    end_sample(d, counts, meas, faults, silence);
}

static uint64_t realtime_silence(const hb_device *d, uint64_t k) {
    uint64_t heard = d->k0 + (d->last_rx_us - d->t0_us) * d->cfg.sample_rate / US_PER_S;
    return k - heard;
}

static uint64_t silence_at(const hb_device *d, uint64_t k, uint64_t now_us) {
    if (d->setup.pacing == HB_REALTIME) return realtime_silence(d, k);
    return ((now_us - d->last_rx_us) * d->cfg.sample_rate + US_PER_S / 2) / US_PER_S;
}

/* Execute one buffered setpoint as sample k: measure, check limits, command, apply. Returns 0, or the
 * fault bits that ended the stream at this sample. */
static uint16_t run_sample(hb_device *d, uint64_t now_us) {
    const float *slot = d->ring + (size_t)d->head * d->vps;
    hb_real u = (hb_real)slot[0];
    hb_real ff = d->vps > 1 ? (hb_real)slot[1] : (hb_real)0;
    d->head = (d->head + 1) % d->slots;
    d->count--;
    int64_t counts;
    hb_real meas;
    hb_hal_measure(d->hal, &counts, &meas);
    uint16_t trip = limit_trips(d, counts, meas, d->cfg.mode == HB_CURRENT ? u : ff);
    if (trip) {
        end_sample(d, counts, meas, trip, silence_at(d, d->index, now_us));
        return trip;
    }
    hb_real position = encoder_position(d, counts);
    hb_real cmd;
    if (d->cfg.mode == HB_VELOCITY) {
        cmd = velocity_loop(d, u, position);
    } else if (d->cfg.mode == HB_POSITION) {
        cmd = position_loop(d, u, ff, position);
    } else {
        cmd = clip(u, d->current_limit);
    }
    remember(d, counts);
    hb_hal_apply(d->hal, cmd, 1);
    d->prev_position = position;
    d->has_prev = 1;
    record(d, counts, cmd, meas, HB_S_ENABLED);
    return 0;
}

static void finish_stream(hb_device *d) {
    if (d->block_n) d->blk_status[d->block_n - 1] |= HB_S_END;
    d->state = HB_ARMED;
    d->current_applied = 0;
    flush_block(d);  /* the header still carries this stream's `received` */
    reset_stream(d);
}

/* First sample index whose nominal time t0 + (k - k0)/rate is after last message + timeout. */
static uint64_t watchdog_trip_index(const hb_device *d) {
    return d->k0 + (d->last_rx_us - d->t0_us + d->watchdog_us) * d->cfg.sample_rate / US_PER_S + 1;
}

void hb_device_tick(hb_device *d, uint64_t now_us) {
    int expired = d->watchdog_us && now_us > d->last_rx_us && now_us - d->last_rx_us > d->watchdog_us;
    if (d->state == HB_ARMED) {
        if (expired) {
            latch(d, HB_F_WATCHDOG, d->index, 0);
            d->state = HB_DISARMED;
            send_status(d, 0);
        }
        return;
    }
    if (d->state != HB_STREAMING) return;
    uint64_t due;
    uint64_t wd = UINT64_MAX;
    if (d->setup.pacing == HB_REALTIME) {
        uint64_t elapsed = now_us > d->t0_us ? (now_us - d->t0_us) * d->cfg.sample_rate / US_PER_S : 0;
        uint64_t done = d->index - d->k0;
        due = elapsed > done ? elapsed - done : 0;
        if (d->watchdog_us) wd = watchdog_trip_index(d);
    } else {
        /* lockstep: as fast as setpoints arrive, bounded per tick so that messages are served between;
         * the watchdog is checked on every tick whatever the buffer holds */
        due = d->count < 4u * d->setup.max_block ? d->count : 4u * d->setup.max_block;
        if (expired) wd = d->index;
    }
    uint16_t faults = 0;
    if (d->setup.pacing == HB_LOCKSTEP && wd <= d->index) {
        faults = HB_F_WATCHDOG;
        end_stream_with(d, faults, silence_at(d, d->index, now_us));
    }
    while (!faults && due > 0 && d->state == HB_STREAMING) {
        if (d->index >= wd) {
            faults = HB_F_WATCHDOG;
            end_stream_with(d, faults, silence_at(d, d->index, now_us));
            break;
        }
        if (d->count == 0) {
            if (d->end_seen) break;
            faults = HB_F_BUFFER_UNDERRUN;
            end_stream_with(d, faults, silence_at(d, d->index, now_us));
            break;
        }
        faults = run_sample(d, now_us);
        due--;
        if (!faults && d->end_seen && d->count == 0) finish_stream(d);
    }
    if (d->state == HB_STREAMING && d->end_seen && d->count == 0) finish_stream(d);  /* an empty last block */
    flush_block(d);
    if (faults) send_status(d, 0);
}

/* ------------------------------------------------------------------ messages */

/* E-stop (faults = ESTOP) or disarm (0): zero current now, one final sample if streaming. */
static void stop(hb_device *d, uint16_t faults) {
    if (d->state == HB_STREAMING) {
        end_stream_with(d, faults, 0);
    } else if (faults) {
        latch(d, faults, d->index, 0);  /* not streaming: the current is already zero */
    }
    if (d->state != HB_UNCONFIGURED) d->state = HB_DISARMED;
    d->current_applied = 0;
}

static uint8_t configure(hb_device *d, const hb_config *c) {
    if (d->state == HB_ARMED || d->state == HB_STREAMING) return HB_BAD_STATE;
    if (!hb_config_valid(c) || hb_hal_configure(d->hal, c) != 0) return HB_INVALID_CONFIG;
    d->cfg = *c;
    d->window = c->sample_rate / 1000 > 1 ? c->sample_rate / 1000 : 1;
    d->watchdog_us = (uint64_t)(c->watchdog_timeout * 1e6 + 0.5);
    d->dt = (hb_real)(1.0 / (double)c->sample_rate);
    double scale = 2.0 * 3.141592653589793 / (double)c->counts_per_rev;
    d->pos_scale = (hb_real)scale;
    d->speed_scale = (hb_real)(scale * (double)c->sample_rate / (double)d->window);
    d->current_limit = (hb_real)c->current_limit;
    d->velocity_limit = (hb_real)c->velocity_limit;
    d->position_min = (hb_real)c->position_min;
    d->position_max = (hb_real)c->position_max;
    d->vps = (c->mode == HB_POSITION && (c->flags & HB_CFG_FEEDFORWARD)) ? 2u : 1u;
    d->slots = d->setup.capacity / d->vps;
    d->d_alpha = c->position_d_cutoff > 0.0 ? (hb_real)exp(-2.0 * 3.141592653589793 * c->position_d_cutoff /
                                                               (double)c->sample_rate) : (hb_real)0;
    d->head = d->count = 0;
    d->index = 0;
    d->current_applied = 0;
    d->has_prev = 0;
    d->pi_integral = 0;
    d->state = HB_DISARMED;
    return HB_OK;
}

static uint8_t arm(hb_device *d) {
    if (d->state == HB_UNCONFIGURED) return HB_NOT_CONFIGURED;
    if (d->faults) return HB_FAULT_LATCHED;
    if (d->state == HB_DISARMED) {
        reset_stream(d);
        d->state = HB_ARMED;
    }
    return HB_OK;
}

static void on_setpoints(hb_device *d, const hb_msg *m, uint64_t now_us) {
    if ((d->state != HB_ARMED && d->state != HB_STREAMING) || d->end_seen) {
        d->dropped_frames++;  /* late blocks after a fault or disarm */
        return;
    }
    uint32_t n = m->n_values / d->vps;  /* samples in the block */
    int bad = m->seq != d->expected_seq || m->n_values % d->vps || n > d->setup.max_block ||
              d->count + n > d->slots;
    for (uint32_t i = 0; !bad && i < m->n_values; i++) bad = !isfinite(hb_get_f32(m->values + 4 * i));
    if (bad) {  /* a lost block, an overflow or garbage: the stream cannot be kept in time */
        d->dropped_frames++;
        if (d->state == HB_STREAMING) {
            end_stream_with(d, HB_F_BUFFER_UNDERRUN, 0);
        } else {
            latch(d, HB_F_BUFFER_UNDERRUN, d->index, 0);
            d->state = HB_DISARMED;
        }
        send_status(d, 0);
        return;
    }
    d->expected_seq++;
    d->received += n;
    for (uint32_t i = 0; i < n; i++) {
        float *slot = d->ring + (size_t)((d->head + d->count + i) % d->slots) * d->vps;
        for (uint32_t j = 0; j < d->vps; j++) slot[j] = hb_get_f32(m->values + 4 * (i * d->vps + j));
    }
    d->count += n;
    d->end_seen = m->end;
    if (d->state == HB_ARMED) {
        d->state = HB_STREAMING;
        d->t0_us = now_us;
        d->k0 = d->index;
    }
}

void hb_device_handle(hb_device *d, uint8_t type, const uint8_t *payload, size_t n, uint64_t now_us) {
    hb_msg m;
    if (hb_msg_decode(type, payload, n, &m) != 0) {
        d->crc_errors++;  /* counted with the link's rejected frames */
        return;
    }
    d->last_rx_us = now_us;
    d->rx_frames++;
    switch (type) {
    case HB_HEARTBEAT:
        send_status(d, m.token);
        return;
    case HB_SETPOINTS:
        on_setpoints(d, &m, now_us);
        return;
    case HB_GET_IDENTITY: {
        /* a new host says which protocol it speaks (v1: nothing); the device answers in that version from
         * now on, up to its own */
        d->identity_requests++;
        d->version = (uint8_t)(m.host_version < HB_PROTOCOL_VERSION_MIN ? HB_PROTOCOL_VERSION_MIN :
                               m.host_version > HB_PROTOCOL_VERSION ? HB_PROTOCOL_VERSION : m.host_version);
        size_t len = hb_identity_encode_sensors(d->setup.model, d->setup.serial, d->setup.firmware,
                                                d->setup.capacity, d->setup.max_block, d->version,
                                                d->setup.sensors, d->payload);
        send(d, HB_IDENTITY, d->payload, len);
        return;
    }
    case HB_GET_CONFIG:
        if (d->state == HB_UNCONFIGURED || (d->version < 2 && d->cfg.mode == HB_POSITION)) {
            send_reply(d, type, HB_NOT_CONFIGURED, d->faults);  /* v1 cannot express position mode */
        } else if (d->version < 2) {
            hb_config_encode_v1(&d->cfg, d->payload);
            send(d, HB_CONFIG, d->payload, HB_CONFIG_BYTES_V1);
        } else {
            hb_config_encode(&d->cfg, d->payload);
            send(d, HB_CONFIG, d->payload, HB_CONFIG_BYTES);
        }
        return;
    case HB_ESTOP:
    case HB_DISARM:
        stop(d, type == HB_ESTOP ? HB_F_ESTOP : 0);
        send_reply(d, type, HB_OK, d->faults);
        return;
    case HB_CLEAR_FAULTS:
        d->faults = 0;
        d->fault_index = 0;
        d->fault_silence = 0;
        send_reply(d, type, HB_OK, 0);
        return;
    case HB_CONFIG: {
        uint8_t result = configure(d, &m.config);
        send_reply(d, type, result, d->faults);
        return;
    }
    case HB_ARM: {
        uint8_t result = arm(d);
        send_reply(d, type, result, d->faults);
        return;
    }
    default:  /* device-to-host types sent to the device */
        send_reply(d, type, HB_BAD_STATE, d->faults);
        return;
    }
}

void hb_device_rx_bytes(hb_device *d, const uint8_t *data, size_t n, uint64_t now_us) {
    uint8_t type;
    const uint8_t *payload;
    size_t len;
    while (hb_frame_decoder_next(&d->decoder, &data, &n, &type, &payload, &len))
        hb_device_handle(d, type, payload, len, now_us);
}

void hb_device_rx_can(hb_device *d, uint16_t id, const uint8_t *data, uint8_t len, uint64_t now_us) {
    uint8_t type;
    const uint8_t *payload;
    size_t n;
    if (hb_can_feed(&d->can, id, data, len, &type, &payload, &n)) hb_device_handle(d, type, payload, n, now_us);
}
