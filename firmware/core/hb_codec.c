/* Protocol v2 (and v1) device side: little-endian fields, CRC-32, COBS, serial frames and the message codec. */
#include "hb_protocol.h"

#include <math.h>
#include <string.h>

void hb_put_u16(uint8_t *p, uint16_t v) { p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); }
void hb_put_u32(uint8_t *p, uint32_t v) { for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i)); }
void hb_put_u64(uint8_t *p, uint64_t v) { for (int i = 0; i < 8; i++) p[i] = (uint8_t)(v >> (8 * i)); }
uint16_t hb_get_u16(const uint8_t *p) { return (uint16_t)(p[0] | p[1] << 8); }
uint32_t hb_get_u32(const uint8_t *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}
uint64_t hb_get_u64(const uint8_t *p) { return (uint64_t)hb_get_u32(p) | (uint64_t)hb_get_u32(p + 4) << 32; }

/* IEEE 754 binary32/binary64 are assumed (true of every target we build for); memcpy keeps it portable
 * across strict aliasing and alignment. */
void hb_put_f32(uint8_t *p, float v) { uint32_t u; memcpy(&u, &v, 4); hb_put_u32(p, u); }
void hb_put_f64(uint8_t *p, double v) { uint64_t u; memcpy(&u, &v, 8); hb_put_u64(p, u); }
float hb_get_f32(const uint8_t *p) { uint32_t u = hb_get_u32(p); float v; memcpy(&v, &u, 4); return v; }
double hb_get_f64(const uint8_t *p) { uint64_t u = hb_get_u64(p); double v; memcpy(&v, &u, 8); return v; }

/* Table-driven CRC-32 (reflected polynomial 0xEDB88320); the 1 KiB table lives in flash. */
static const uint32_t crc_table[256] = {
#define C1(c) (((c) >> 1) ^ (0xEDB88320u & (0u - ((c) & 1u))))  /* c twice, not 3 times: 2^8 expansions, not 3^8 */
#define C8(c) C1(C1(C1(C1(C1(C1(C1(C1((uint32_t)(c)))))))))
#define R4(i) C8(i), C8(i + 1), C8(i + 2), C8(i + 3)
#define R16(i) R4(i), R4(i + 4), R4(i + 8), R4(i + 12)
#define R64(i) R16(i), R16(i + 16), R16(i + 32), R16(i + 48)
    R64(0), R64(64), R64(128), R64(192)
#undef R64
#undef R16
#undef R4
#undef C8
#undef C1
};

uint32_t hb_crc32(uint32_t crc, const uint8_t *data, size_t n) {
    crc = ~crc;
    for (size_t i = 0; i < n; i++) crc = crc_table[(crc ^ data[i]) & 0xFFu] ^ (crc >> 8);
    return ~crc;
}

/* COBS as the `cobs` Python package writes it: a run of 254 non-zero bytes at the very end is not
 * followed by an empty block. */
size_t hb_cobs_encode(const uint8_t *in, size_t n, uint8_t *out) {
    size_t o = 1, code_pos = 0;
    uint8_t code = 1;
    int final_zero = 1;
    for (size_t i = 0; i < n; i++) {
        if (in[i] == 0) {
            out[code_pos] = code;
            code_pos = o++;
            code = 1;
            final_zero = 1;
        } else {
            out[o++] = in[i];
            if (++code == 0xFF) {
                out[code_pos] = code;
                code_pos = o++;
                code = 1;
                final_zero = 0;
            }
        }
    }
    if (code != 1 || final_zero) {
        out[code_pos] = code;
        return o;
    }
    return o - 1;
}

long hb_cobs_decode(const uint8_t *in, size_t n, uint8_t *out) {
    size_t i = 0, o = 0;
    while (i < n) {
        uint8_t code = in[i++];
        if (code == 0) return -1;
        size_t end = i + code - 1;
        if (end > n) return -1;
        for (; i < end; i++) {
            if (in[i] == 0) return -1;
            out[o++] = in[i];
        }
        if (i < n && code < 0xFF) out[o++] = 0;
    }
    return (long)o;
}

size_t hb_frame_encode(uint8_t type, const uint8_t *payload, size_t n, uint8_t *out) {
    return hb_frame_encode_version(HB_PROTOCOL_VERSION, type, payload, n, out);
}

size_t hb_frame_encode_version(uint8_t version, uint8_t type, const uint8_t *payload, size_t n, uint8_t *out) {
    if (n + 6 > HB_MAX_FRAME) return 0;
    /* the raw frame is assembled at the end of `out` and encoded towards its start: COBS never moves a
     * byte forward by more than its overhead, which the gap covers */
    size_t cap = HB_COBS_MAX(n + 6);
    uint8_t *raw = out + cap - (n + 6);
    raw[0] = version;
    raw[1] = type;
    if (n) memmove(raw + 2, payload, n);
    hb_put_u32(raw + 2 + n, hb_crc32(0, raw, n + 2));
    size_t len = hb_cobs_encode(raw, n + 6, out);
    out[len] = 0;
    return len + 1;
}

void hb_frame_decoder_init(hb_frame_decoder *d) {
    d->len = 0;
    d->discarding = 0;
    d->crc_errors = 0;
    d->frames = 0;
    d->version = HB_PROTOCOL_VERSION;
}

int hb_frame_decoder_next(hb_frame_decoder *d, const uint8_t **data, size_t *n, uint8_t *type,
                          const uint8_t **payload, size_t *len) {
    while (*n) {
        uint8_t b = **data;
        (*data)++;
        (*n)--;
        if (b != 0) {
            if (d->discarding) continue;
            if (d->len >= sizeof d->enc) {  /* oversize: drop it and resynchronise at the next 0x00 */
                d->discarding = 1;
                d->len = 0;
                d->crc_errors++;
                continue;
            }
            d->enc[d->len++] = b;
            continue;
        }
        uint32_t flen = d->len;
        d->len = 0;
        if (d->discarding) {
            d->discarding = 0;
            continue;
        }
        if (flen == 0) continue;  /* empty frame: idle line or a sender's resync */
        long rlen = hb_cobs_decode(d->enc, flen, d->raw);
        if (rlen < 6 || hb_crc32(0, d->raw, (size_t)rlen - 4) != hb_get_u32(d->raw + rlen - 4) ||
            d->raw[0] < HB_PROTOCOL_VERSION_MIN || d->raw[0] > HB_PROTOCOL_VERSION) {
            d->crc_errors++;
            continue;
        }
        d->frames++;
        d->version = d->raw[0];
        *type = d->raw[1];
        *payload = d->raw + 2;
        *len = (size_t)rlen - 6;
        return 1;
    }
    return 0;
}

void hb_config_decode(const uint8_t *in, size_t n, hb_config *c) {
    c->sample_rate = hb_get_u32(in);
    c->mode = in[4];
    c->current_limit = hb_get_f64(in + 5);
    c->velocity_limit = hb_get_f64(in + 13);
    c->position_min = hb_get_f64(in + 21);
    c->position_max = hb_get_f64(in + 29);
    c->watchdog_timeout = hb_get_f64(in + 37);
    c->torque_constant = hb_get_f64(in + 45);
    c->counts_per_rev = hb_get_u32(in + 53);
    c->ratio = hb_get_f64(in + 57);
    int v2 = n >= HB_CONFIG_BYTES;
    c->position_kp = v2 ? hb_get_f64(in + 65) : 0.0;
    c->position_ki = v2 ? hb_get_f64(in + 73) : 0.0;
    c->position_kd = v2 ? hb_get_f64(in + 81) : 0.0;
    c->position_i_limit = v2 ? hb_get_f64(in + 89) : 0.0;
    c->position_d_cutoff = v2 ? hb_get_f64(in + 97) : 0.0;
    c->flags = v2 ? in[105] : 0;
}

void hb_config_encode(const hb_config *c, uint8_t *out) {
    hb_config_encode_v1(c, out);
    hb_put_f64(out + 65, c->position_kp);
    hb_put_f64(out + 73, c->position_ki);
    hb_put_f64(out + 81, c->position_kd);
    hb_put_f64(out + 89, c->position_i_limit);
    hb_put_f64(out + 97, c->position_d_cutoff);
    out[105] = c->flags;
}

void hb_config_encode_v1(const hb_config *c, uint8_t *out) {
    hb_put_u32(out, c->sample_rate);
    out[4] = c->mode;
    hb_put_f64(out + 5, c->current_limit);
    hb_put_f64(out + 13, c->velocity_limit);
    hb_put_f64(out + 21, c->position_min);
    hb_put_f64(out + 29, c->position_max);
    hb_put_f64(out + 37, c->watchdog_timeout);
    hb_put_f64(out + 45, c->torque_constant);
    hb_put_u32(out + 53, c->counts_per_rev);
    hb_put_f64(out + 57, c->ratio);
}

static int positive_finite(double v) { return isfinite(v) && v > 0.0; }
static int nonnegative_finite(double v) { return isfinite(v) && v >= 0.0; }

int hb_config_valid(const hb_config *c) {
    uint32_t r = c->sample_rate;
    if (r != 1000 && r != 2000 && r != 5000 && r != 10000 && r != 20000) return 0;
    if (c->mode != HB_CURRENT && c->mode != HB_VELOCITY && c->mode != HB_POSITION) return 0;
    if (!nonnegative_finite(c->position_kp) || !nonnegative_finite(c->position_ki) ||
        !nonnegative_finite(c->position_kd) || !nonnegative_finite(c->position_i_limit)) return 0;
    /* the derivative filter's cut-off stays below Nyquist (0 = unfiltered) */
    if (!nonnegative_finite(c->position_d_cutoff) || c->position_d_cutoff >= 0.5 * (double)r) return 0;
    if (c->flags & ~(unsigned)HB_CFG_FEEDFORWARD) return 0;
    if (c->flags && c->mode != HB_POSITION) return 0;  /* feed-forward is a position-mode option */
    if (c->mode == HB_POSITION && !(c->position_kp > 0.0)) return 0;  /* no loop, no position mode */
    if (!positive_finite(c->current_limit) || !positive_finite(c->velocity_limit) ||
        !positive_finite(c->torque_constant) || !positive_finite(c->ratio)) return 0;
    if (isnan(c->position_min) || isnan(c->position_max) || !(c->position_min < c->position_max)) return 0;
    if (!(isfinite(c->watchdog_timeout) && c->watchdog_timeout >= 0.0)) return 0;
    return c->counts_per_rev > 0;
}

static int identity_layout_ok(const uint8_t *p, size_t n) {
    size_t pos = 0;
    for (int i = 0; i < 3; i++) {
        if (pos >= n) return 0;
        pos += 1 + (size_t)p[pos];
        if (pos > n) return 0;
    }
    return n - pos == 8 || n - pos == 9;  /* v3 adds the sensors byte */
}

int hb_msg_decode(uint8_t type, const uint8_t *p, size_t n, hb_msg *msg) {
    msg->type = type;
    switch (type) {
    case HB_ESTOP: case HB_DISARM: case HB_ARM: case HB_CLEAR_FAULTS: case HB_GET_CONFIG:
        return n == 0 ? 0 : -1;
    case HB_GET_IDENTITY:  /* v1: empty; v2: the host's protocol version, u16 */
        if (n != 0 && n != 2) return -1;
        msg->host_version = n ? hb_get_u16(p) : 1;
        return 0;
    case HB_CONFIG:
        if (n != HB_CONFIG_BYTES && n != HB_CONFIG_BYTES_V1) return -1;
        hb_config_decode(p, n, &msg->config);
        msg->config_version = n == HB_CONFIG_BYTES ? 2 : 1;
        return 0;
    case HB_HEARTBEAT:
        if (n != 4) return -1;
        msg->token = hb_get_u32(p);
        return 0;
    case HB_SETPOINTS:
        if (n < 5 || (p[4] & ~1u) || (n - 5) % 4) return -1;
        msg->seq = hb_get_u32(p);
        msg->end = p[4] & 1u;
        msg->n_values = (uint32_t)((n - 5) / 4);
        msg->values = p + 5;
        return 0;
    case HB_IDENTITY:
        return identity_layout_ok(p, n) ? 0 : -1;
    case HB_STATUS:
        return n == HB_STATUS_BYTES ? 0 : -1;
    case HB_REPLY:
        return n == 4 ? 0 : -1;
    case HB_SAMPLES:
        /* the two header sizes differ by 4 bytes, never a whole number of 14-byte samples: unambiguous */
        if (n >= HB_SAMPLES_HEADER_BYTES && (n - HB_SAMPLES_HEADER_BYTES) % HB_SAMPLE_BYTES == 0) return 0;
        return n >= HB_SAMPLES_HEADER_BYTES_V3 && (n - HB_SAMPLES_HEADER_BYTES_V3) % HB_SAMPLE_BYTES == 0 ? 0 : -1;
    default:
        return -1;
    }
}

void hb_status_encode(const hb_status *s, uint8_t *out) {
    hb_put_u32(out, s->token);
    out[4] = s->state;
    hb_put_u16(out + 5, s->faults);
    hb_put_u64(out + 7, s->index);
    hb_put_u32(out + 15, s->free);
    hb_put_u64(out + 19, s->received);
    hb_put_u64(out + 27, s->fault_index);
    hb_put_u64(out + 35, s->fault_silence);
    hb_put_f32(out + 43, s->current_applied);
    hb_put_u32(out + 47, s->crc_errors);
    hb_put_u32(out + 51, s->dropped_frames);
    hb_put_u32(out + 55, s->rx_frames);
    hb_put_u32(out + 59, s->tx_frames);
}

void hb_reply_encode(uint8_t request, uint8_t result, uint16_t faults, uint8_t *out) {
    out[0] = request;
    out[1] = result;
    hb_put_u16(out + 2, faults);
}

size_t hb_identity_encode(const char *model, const char *serial, const char *firmware, uint32_t capacity,
                          uint16_t max_block, uint8_t *out) {
    return hb_identity_encode_version(model, serial, firmware, capacity, max_block, HB_PROTOCOL_VERSION, out);
}

size_t hb_identity_encode_version(const char *model, const char *serial, const char *firmware, uint32_t capacity,
                                  uint16_t max_block, uint16_t version, uint8_t *out) {
    return hb_identity_encode_sensors(model, serial, firmware, capacity, max_block, version, 0, out);
}

size_t hb_identity_encode_sensors(const char *model, const char *serial, const char *firmware, uint32_t capacity,
                                  uint16_t max_block, uint16_t version, uint8_t sensors, uint8_t *out) {
    const char *texts[3] = {model, serial, firmware};
    size_t pos = 0;
    for (int i = 0; i < 3; i++) {
        size_t len = strlen(texts[i]);
        if (len > 255) len = 255;
        out[pos++] = (uint8_t)len;
        memcpy(out + pos, texts[i], len);
        pos += len;
    }
    hb_put_u16(out + pos, version);
    hb_put_u32(out + pos + 2, capacity);
    hb_put_u16(out + pos + 6, max_block);
    if (version < 3) return pos + 8;
    out[pos + 8] = sensors;
    return pos + 9;
}

void hb_samples_header_encode(const hb_samples_header *h, uint8_t *out) {
    hb_put_u32(out, h->seq);
    hb_put_u64(out + 4, h->first_index);
    hb_put_u32(out + 12, h->free);
    hb_put_u64(out + 16, h->received);
    hb_put_u16(out + 24, h->faults);
    out[26] = h->state;
}

size_t hb_samples_header_encode_version(const hb_samples_header *h, uint8_t version, uint8_t *out) {
    hb_samples_header_encode(h, out);
    if (version < 3) return HB_SAMPLES_HEADER_BYTES;
    hb_put_f32(out + HB_SAMPLES_HEADER_BYTES, h->temperature);
    return HB_SAMPLES_HEADER_BYTES_V3;
}
