/* Unit tests of the firmware core on the host, with a scripted HAL (fake_hal.c).
 *
 * Usage: test_core DIR   (DIR = tests/data/protocol, the golden frames written by the Python codec)
 * Prints one line per failed check and "N checks, M failed"; exit status 1 on any failure.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fake_hal.h"
#include "hb_can.h"
#include "hb_device.h"
#include "hb_protocol.h"

static int checks, failures;
#define CHECK(cond) check((cond), #cond, __FILE__, __LINE__)
static void check(int ok, const char *what, const char *file, int line) {
    checks++;
    if (!ok) {
        failures++;
        printf("FAIL %s:%d: %s\n", file, line, what);
    }
}

/* ------------------------------------------------------------------ output parsing */

typedef struct {
    size_t n_samples, n_blocks, n_status, n_replies;
    int32_t counts[16384];
    float cmd[16384], meas[16384];
    uint16_t status[16384];
    uint64_t first[512];
    uint8_t block_state[512];
    float block_temperature[512];  /* v3 headers; NaN from a v1/v2 one */
    uint8_t reply[64][4];
    uint8_t last_status[HB_STATUS_BYTES];
} output;

static hb_device dev;
static fake_hal hal;
static output out;
static uint8_t raw[HB_MAX_FRAME * 2];

/* Parse (and consume) everything the device wrote; frames are checked independently of the decoder. */
static void parse(fake_hal *f, output *o) {
    memset(o, 0, sizeof *o);
    size_t start = 0;
    for (size_t i = 0; i < f->tx_len; i++) {
        if (f->tx[i] != 0) continue;
        long n = hb_cobs_decode(f->tx + start, i - start, raw);
        start = i + 1;
        CHECK(n >= 6);
        CHECK(raw[0] == dev.version);  /* the device answers in the version its host named */
        CHECK(hb_crc32(0, raw, (size_t)n - 4) == hb_get_u32(raw + n - 4));
        const uint8_t *p = raw + 2;
        size_t len = (size_t)n - 6;
        if (raw[1] == HB_SAMPLES) {
            size_t head = raw[0] >= 3 ? HB_SAMPLES_HEADER_BYTES_V3 : HB_SAMPLES_HEADER_BYTES;
            CHECK((len - head) % HB_SAMPLE_BYTES == 0);
            size_t k = (len - head) / HB_SAMPLE_BYTES;
            o->first[o->n_blocks] = hb_get_u64(p + 4);
            o->block_temperature[o->n_blocks] = raw[0] >= 3 ? hb_get_f32(p + 27) : NAN;
            o->block_state[o->n_blocks++] = p[26];
            const uint8_t *b = p + head;
            for (size_t j = 0; j < k; j++) {
                size_t s = o->n_samples++;
                o->counts[s] = (int32_t)hb_get_u32(b + 4 * j);
                o->cmd[s] = hb_get_f32(b + 4 * (k + j));
                o->meas[s] = hb_get_f32(b + 4 * (2 * k + j));
                o->status[s] = hb_get_u16(b + 12 * k + 2 * j);
            }
        } else if (raw[1] == HB_STATUS) {
            o->n_status++;
            memcpy(o->last_status, p, HB_STATUS_BYTES);
        } else if (raw[1] == HB_REPLY && o->n_replies < 64) {
            memcpy(o->reply[o->n_replies++], p, 4);
        }
    }
    f->tx_len = 0;
}

/* ------------------------------------------------------------------ host side */

static uint8_t frame[HB_COBS_MAX(HB_MAX_FRAME)];

static void host_send(hb_device *d, uint8_t type, const uint8_t *payload, size_t n, uint64_t t_us) {
    size_t len = hb_frame_encode(type, payload, n, frame);
    hb_device_rx_bytes(d, frame, len, t_us);
}

static void send_empty(hb_device *d, uint8_t type, uint64_t t_us) { host_send(d, type, NULL, 0, t_us); }

static void send_config(hb_device *d, uint32_t rate, uint8_t mode, double current_limit, double velocity_limit,
                        double pmin, double pmax, double watchdog, uint32_t cpr, uint64_t t_us) {
    hb_config c = {rate, mode, current_limit, velocity_limit, pmin, pmax, watchdog, 0.2, cpr, 1.0, 0, 0, 0, 0, 0, 0};
    uint8_t p[HB_CONFIG_BYTES];
    hb_config_encode(&c, p);
    host_send(d, HB_CONFIG, p, sizeof p, t_us);
}

static void send_block(hb_device *d, uint32_t seq, const float *v, uint32_t n, int end, uint64_t t_us) {
    static uint8_t p[5 + 4 * 4096];
    hb_put_u32(p, seq);
    p[4] = end ? 1 : 0;
    for (uint32_t i = 0; i < n; i++) hb_put_f32(p + 5 + 4 * i, v[i]);
    host_send(d, HB_SETPOINTS, p, 5 + 4 * (size_t)n, t_us);
}


static void fresh(uint8_t pacing, uint32_t rate, uint8_t mode, double watchdog) {
    memset(&hal, 0, sizeof hal);
    hal.gain = 1.0;
    hb_device_setup s = {"HB-TEST", "T-1", "test", 4096, 128, pacing, HB_LINK_SERIAL, 1, 0.5, 20.0, 0};
    hb_device_init(&dev, &s, &hal);
    send_config(&dev, rate, mode, 5.0, 1e4, -INFINITY, INFINITY, watchdog, 4096, 0);
    send_empty(&dev, HB_ARM, 0);
    parse(&hal, &out);
    CHECK(out.n_replies == 2 && out.reply[0][1] == HB_OK && out.reply[1][1] == HB_OK);
}

static float ones[4096];

/* ------------------------------------------------------------------ tests */

static void test_crc32_and_cobs(void) {
    CHECK(hb_crc32(0, (const uint8_t *)"123456789", 9) == 0xCBF43926u);  /* the CRC-32 check value */
    uint8_t enc[600], dec[600];
    static const uint8_t a[] = {0x11, 0x22, 0x00, 0x33}, ea[] = {0x03, 0x11, 0x22, 0x02, 0x33};
    CHECK(hb_cobs_encode(a, 4, enc) == 5 && memcmp(enc, ea, 5) == 0);
    static const uint8_t z[] = {0x00, 0x00}, ez[] = {0x01, 0x01, 0x01};
    CHECK(hb_cobs_encode(z, 2, enc) == 3 && memcmp(enc, ez, 3) == 0);
    uint8_t run[254];
    for (int i = 0; i < 254; i++) run[i] = (uint8_t)(i + 1);
    size_t n = hb_cobs_encode(run, 254, enc);  /* no empty block after a final run of 254 */
    CHECK(n == 255 && enc[0] == 0xFF && memcmp(enc + 1, run, 254) == 0);
    CHECK(hb_cobs_decode(enc, n, dec) == 254 && memcmp(dec, run, 254) == 0);
    static const uint8_t bad[] = {0x05, 0x11};
    CHECK(hb_cobs_decode(bad, 2, dec) == -1);
}

static size_t read_hex_version(const char *dir, int version, const char *name, uint8_t *buf) {
    char path[1024];
    snprintf(path, sizeof path, "%s/v%d_%s.hex", dir, version, name);
    FILE *fp = fopen(path, "r");
    if (!fp) {
        printf("FAIL cannot open %s\n", path);
        failures++;
        return 0;
    }
    size_t n = 0;
    unsigned v;
    while (fscanf(fp, "%2x", &v) == 1) buf[n++] = (uint8_t)v;
    fclose(fp);
    return n;
}

static size_t read_hex(const char *dir, const char *name, uint8_t *buf) { return read_hex_version(dir, 1, name, buf); }

static int golden_equals_version(const char *dir, int version, const char *name, uint8_t type, const uint8_t *payload,
                                 size_t n) {
    static uint8_t want[4096], got[4096];
    size_t wn = read_hex_version(dir, version, name, want);
    size_t gn = hb_frame_encode_version((uint8_t)version, type, payload, n, got);
    return wn == gn && memcmp(want, got, wn) == 0;
}

static int golden_equals(const char *dir, const char *name, uint8_t type, const uint8_t *payload, size_t n) {
    return golden_equals_version(dir, 1, name, type, payload, n);
}

/* Device-to-host frames are encoded byte-identically; host-to-device frames decode to the values of
 * tests/drivers/protocol_examples.py. */
static void test_golden_frames(const char *dir) {
    uint8_t p[1024];
    size_t n = hb_identity_encode_version("HB-AMP-1", "SIM-0001", "1.0.0+sim", 8192, 256, 1, p);
    CHECK(golden_equals(dir, "identity", HB_IDENTITY, p, n));
    n = hb_identity_encode_version("HB-AMP-1", "SIM-0001", "1.0.0+sim", 8192, 256, 2, p);
    CHECK(golden_equals_version(dir, 2, "identity", HB_IDENTITY, p, n));
    n = hb_identity_encode_sensors("HB-AMP-1", "SIM-0001", "1.0.0+sim", 8192, 256, 3, HB_SENSOR_TEMPERATURE, p);
    CHECK(golden_equals_version(dir, 3, "identity", HB_IDENTITY, p, n));
    hb_config c = {10000, HB_VELOCITY, 4.5, 150.0, -INFINITY, 12.5, 0.1, 0.0452, 16384, 3.0, 0, 0, 0, 0, 0, 0};
    hb_config_encode_v1(&c, p);
    CHECK(golden_equals(dir, "config", HB_CONFIG, p, HB_CONFIG_BYTES_V1));
    hb_config cp = {20000, HB_POSITION, 8.0, 300.0, -0.5, 0.75, 0.5, 0.2, 65536, 1.0,
                    2500.0, 125000.0, 4.5, 3.25, 250.0, HB_CFG_FEEDFORWARD};
    hb_config_encode(&cp, p);
    CHECK(golden_equals_version(dir, 2, "config_position", HB_CONFIG, p, HB_CONFIG_BYTES));
    hb_status s = {7, HB_STREAMING, HB_F_WATCHDOG | HB_F_OVER_SPEED, 600000, 600192, 599000, 1001, 8000, 0.0f,
                   3, 2, 5000, 6000};
    hb_status_encode(&s, p);
    CHECK(golden_equals(dir, "status", HB_STATUS, p, HB_STATUS_BYTES));
    hb_reply_encode(HB_ARM, HB_FAULT_LATCHED, HB_F_ESTOP, p);
    CHECK(golden_equals(dir, "reply", HB_REPLY, p, 4));
    hb_samples_header h = {3, 100, (1ull << 33) + 5, (1ull << 33) + 9, 0, HB_STREAMING, NAN};
    hb_samples_header_encode(&h, p);
    int32_t counts[4] = {0, -1, 2147483647, -2147483647 - 1};
    float cmd[4] = {0.5f, 0.0f, -0.25f, 1.0f}, meas[4] = {0.49f, 0.01f, -0.26f, 0.99f};
    uint16_t st[4] = {1, 1, 3, 5};
    uint8_t *b = p + HB_SAMPLES_HEADER_BYTES;
    for (int i = 0; i < 4; i++) {
        hb_put_u32(b + 4 * i, (uint32_t)counts[i]);
        hb_put_f32(b + 16 + 4 * i, cmd[i]);
        hb_put_f32(b + 32 + 4 * i, meas[i]);
        hb_put_u16(b + 48 + 2 * i, st[i]);
    }
    CHECK(golden_equals(dir, "samples", HB_SAMPLES, p, HB_SAMPLES_HEADER_BYTES + 4 * HB_SAMPLE_BYTES));
    /* v3: the same samples after a header 4 bytes longer, the temperature f32 at offset 27 */
    uint8_t q[1024];
    h.temperature = 36.625f;
    CHECK(hb_samples_header_encode_version(&h, 3, q) == HB_SAMPLES_HEADER_BYTES_V3);
    memcpy(q + HB_SAMPLES_HEADER_BYTES_V3, b, 4 * HB_SAMPLE_BYTES);
    CHECK(golden_equals_version(dir, 3, "samples", HB_SAMPLES, q, HB_SAMPLES_HEADER_BYTES_V3 + 4 * HB_SAMPLE_BYTES));
    CHECK(hb_samples_header_encode_version(&h, 2, q) == HB_SAMPLES_HEADER_BYTES && memcmp(q, p, 27) == 0);

    static const struct { const char *name; uint8_t type; } empty[] = {
        {"estop", HB_ESTOP}, {"disarm", HB_DISARM}, {"arm", HB_ARM}, {"clear_faults", HB_CLEAR_FAULTS},
        {"get_config", HB_GET_CONFIG}, {"get_identity", HB_GET_IDENTITY}};
    static hb_frame_decoder d;
    uint8_t buf[4096], type;
    const uint8_t *payload;
    size_t len;
    hb_msg m;
    for (size_t i = 0; i < sizeof empty / sizeof empty[0]; i++) {
        hb_frame_decoder_init(&d);
        const uint8_t *data = buf;
        size_t left = read_hex(dir, empty[i].name, buf);
        CHECK(hb_frame_decoder_next(&d, &data, &left, &type, &payload, &len) == 1);
        CHECK(type == empty[i].type && len == 0 && hb_msg_decode(type, payload, len, &m) == 0);
    }
    hb_frame_decoder_init(&d);
    const uint8_t *data = buf;
    size_t left = read_hex(dir, "heartbeat", buf);
    CHECK(hb_frame_decoder_next(&d, &data, &left, &type, &payload, &len) == 1);
    CHECK(hb_msg_decode(type, payload, len, &m) == 0 && m.type == HB_HEARTBEAT && m.token == 0xDEADBEEFu);
    data = buf;
    left = read_hex(dir, "setpoints", buf);
    CHECK(hb_frame_decoder_next(&d, &data, &left, &type, &payload, &len) == 1);
    CHECK(hb_msg_decode(type, payload, len, &m) == 0 && m.seq == 41 && m.end == 1 && m.n_values == 4);
    CHECK(hb_get_f32(m.values) == 0.0f && hb_get_f32(m.values + 4) == -1.5f && hb_get_f32(m.values + 8) == 2.25f &&
          hb_get_f32(m.values + 12) == 1e-3f);
    data = buf;
    left = read_hex(dir, "config", buf);
    CHECK(hb_frame_decoder_next(&d, &data, &left, &type, &payload, &len) == 1);
    CHECK(hb_msg_decode(type, payload, len, &m) == 0 && m.config.sample_rate == 10000 && m.config.mode == 1 &&
          m.config.current_limit == 4.5 && isinf(m.config.position_min) && m.config.position_max == 12.5 &&
          m.config.counts_per_rev == 16384 && m.config.ratio == 3.0);
    CHECK(m.config_version == 1 && m.config.position_kp == 0.0 && m.config.flags == 0);
    /* protocol v2: GET_IDENTITY names the host's version (v1: empty), CONFIG carries the position loop,
     * position setpoints interleave angle and feed-forward current */
    data = buf;
    left = read_hex(dir, "get_identity", buf);
    CHECK(hb_frame_decoder_next(&d, &data, &left, &type, &payload, &len) == 1 && d.version == 1);
    CHECK(hb_msg_decode(type, payload, len, &m) == 0 && m.host_version == 1);
    data = buf;
    left = read_hex_version(dir, 2, "get_identity", buf);
    CHECK(hb_frame_decoder_next(&d, &data, &left, &type, &payload, &len) == 1 && d.version == 2);
    CHECK(hb_msg_decode(type, payload, len, &m) == 0 && m.host_version == 2);
    data = buf;
    left = read_hex_version(dir, 2, "config_position", buf);
    CHECK(hb_frame_decoder_next(&d, &data, &left, &type, &payload, &len) == 1);
    CHECK(hb_msg_decode(type, payload, len, &m) == 0 && m.config_version == 2 && m.config.mode == HB_POSITION &&
          m.config.position_kp == 2500.0 && m.config.position_ki == 125000.0 && m.config.position_kd == 4.5 &&
          m.config.position_i_limit == 3.25 && m.config.position_d_cutoff == 250.0 &&
          m.config.flags == HB_CFG_FEEDFORWARD && m.config.position_min == -0.5 && hb_config_valid(&m.config));
    data = buf;
    left = read_hex_version(dir, 2, "setpoints_position", buf);
    CHECK(hb_frame_decoder_next(&d, &data, &left, &type, &payload, &len) == 1);
    CHECK(hb_msg_decode(type, payload, len, &m) == 0 && m.seq == 7 && m.end == 0 && m.n_values == 6);
    CHECK(hb_get_f32(m.values + 4) == 0.5f && hb_get_f32(m.values + 8) == 2.5e-4f &&
          hb_get_f32(m.values + 20) == 1.25f);
    /* one flipped bit anywhere is rejected and counted, and the next frame still decodes */
    size_t good = read_hex(dir, "heartbeat", buf);
    buf[3] ^= 0x10;
    memcpy(buf + good, buf, good);
    buf[good + 3] ^= 0x10;
    data = buf;
    left = 2 * good;
    uint32_t before = d.crc_errors;
    CHECK(hb_frame_decoder_next(&d, &data, &left, &type, &payload, &len) == 1 && d.crc_errors == before + 1);
}

/* Realtime: t0 = 100.0 s, last message at 100.0 s, timeout 0.1 s at 1 kHz: sample 101 is the first
 * after the deadline, its current is zero, it carries FAULT|END; 101 samples of silence. */
static void test_realtime_watchdog_index(void) {
    fresh(HB_REALTIME, 1000, HB_CURRENT, 0.1);
    for (uint32_t k = 0; k < 8; k++) send_block(&dev, k, ones, 128, 0, 100000000);
    hb_device_tick(&dev, 100500000);
    parse(&hal, &out);
    CHECK(out.n_samples == 102);
    int ok = 1;
    for (int k = 0; k < 101; k++) ok &= out.cmd[k] == 1.0f && out.status[k] == HB_S_ENABLED;
    CHECK(ok);
    CHECK(out.cmd[101] == 0.0f && out.status[101] == (HB_S_FAULT | HB_S_END));
    CHECK(dev.faults == HB_F_WATCHDOG && dev.fault_index == 101 && dev.fault_silence == 101);
    CHECK(dev.state == HB_DISARMED && out.n_status == 1 && hal.enabled == 0);
}

/* Realtime, the samples computed reach the watchdog's sample exactly at a tick boundary: the next tick
 * trips at that sample with nothing left to take (the Python firmware's _take(0)). */
static void test_watchdog_at_a_block_boundary(void) {
    fresh(HB_REALTIME, 1000, HB_CURRENT, 0.1);
    for (uint32_t k = 0; k < 8; k++) send_block(&dev, k, ones, 128, 0, 0);
    hb_device_tick(&dev, 101000);  /* samples 0..100: the watchdog sample is 101 */
    parse(&hal, &out);
    CHECK(out.n_samples == 101 && dev.state == HB_STREAMING && dev.index == 101);
    hb_device_tick(&dev, 150000);
    parse(&hal, &out);
    CHECK(out.n_samples == 1 && out.status[0] == (HB_S_FAULT | HB_S_END) && out.cmd[0] == 0.0f);
    CHECK(dev.faults == HB_F_WATCHDOG && dev.fault_index == 101);
}

/* Lockstep: the watchdog trips with an empty buffer (the stream waits for setpoints that never come). */
static void test_lockstep_watchdog_with_empty_buffer(void) {
    fresh(HB_LOCKSTEP, 1000, HB_CURRENT, 0.5);
    send_block(&dev, 0, ones, 10, 0, 1000000);
    hb_device_tick(&dev, 1000000);
    parse(&hal, &out);
    CHECK(out.n_samples == 10 && dev.state == HB_STREAMING && dev.count == 0);
    hb_device_tick(&dev, 1400000);  /* 0.4 s of silence: not yet */
    parse(&hal, &out);
    CHECK(out.n_samples == 0 && dev.faults == 0);
    hb_device_tick(&dev, 1500001);
    parse(&hal, &out);
    CHECK(out.n_samples == 1 && out.status[0] == (HB_S_FAULT | HB_S_END) && out.cmd[0] == 0.0f);
    CHECK(dev.faults == HB_F_WATCHDOG && dev.fault_index == 10 && dev.fault_silence == 500);
    CHECK(dev.state == HB_DISARMED && out.n_status == 1);
    /* an armed, idle device trips too */
    send_empty(&dev, HB_CLEAR_FAULTS, 2000000);
    send_empty(&dev, HB_ARM, 2000000);
    hb_device_tick(&dev, 2600000);
    CHECK(dev.faults == HB_F_WATCHDOG && dev.state == HB_DISARMED);
}

static void test_underrun_gap_and_overflow(void) {
    fresh(HB_REALTIME, 1000, HB_CURRENT, 0.0);
    float half[64];
    for (int i = 0; i < 64; i++) half[i] = 0.5f;
    send_block(&dev, 0, half, 50, 0, 0);
    hb_device_tick(&dev, 200000);  /* 200 samples due, 50 buffered */
    parse(&hal, &out);
    CHECK(out.n_samples == 51 && out.cmd[50] == 0.0f && out.status[50] == (HB_S_FAULT | HB_S_END));
    CHECK(dev.faults == HB_F_BUFFER_UNDERRUN && dev.fault_index == 50);
    send_empty(&dev, HB_CLEAR_FAULTS, 300000);
    send_empty(&dev, HB_ARM, 300000);
    send_block(&dev, 0, half, 10, 0, 300000);
    send_block(&dev, 2, half, 10, 0, 300000);  /* block 1 lost on the link */
    parse(&hal, &out);
    CHECK(out.n_samples == 1 && out.cmd[0] == 0.0f && dev.faults == HB_F_BUFFER_UNDERRUN);
    CHECK(dev.dropped_frames == 1);
    /* credit: 4096 slots; a block that would overflow them is refused */
    send_empty(&dev, HB_CLEAR_FAULTS, 400000);
    send_empty(&dev, HB_ARM, 400000);
    for (uint32_t k = 0; k < 32; k++) send_block(&dev, k, ones, 128, 0, 400000);
    hb_status s;
    hb_device_status(&dev, 0, &s);
    CHECK(s.free == 0 && s.received == 4096);
    send_block(&dev, 32, ones, 1, 0, 400000);
    CHECK(dev.faults == HB_F_BUFFER_UNDERRUN);
    /* a non-finite setpoint */
    send_empty(&dev, HB_CLEAR_FAULTS, 500000);
    send_empty(&dev, HB_ARM, 500000);
    float nan_block[2] = {1.0f, NAN};
    send_block(&dev, 0, nan_block, 2, 1, 500000);
    CHECK(dev.faults == HB_F_BUFFER_UNDERRUN && dev.state == HB_DISARMED);
}

static void test_estop_disarm_and_latching(void) {
    fresh(HB_LOCKSTEP, 1000, HB_CURRENT, 0.0);
    float two[100];
    for (int i = 0; i < 100; i++) two[i] = 2.0f;
    send_block(&dev, 0, two, 100, 0, 0);
    hb_device_tick(&dev, 0);
    send_empty(&dev, HB_DISARM, 0);
    parse(&hal, &out);
    CHECK(out.n_samples == 101 && out.cmd[100] == 0.0f && out.status[100] == HB_S_END);
    CHECK(dev.faults == 0 && dev.state == HB_DISARMED && hal.enabled == 0);
    send_empty(&dev, HB_ARM, 0);
    send_block(&dev, 0, two, 100, 0, 0);
    send_empty(&dev, HB_ESTOP, 0);
    parse(&hal, &out);
    CHECK(out.n_samples == 1 && out.status[0] == (HB_S_FAULT | HB_S_END));
    CHECK(out.n_replies == 2 && out.reply[1][0] == HB_ESTOP && out.reply[1][1] == HB_OK &&
          hb_get_u16(out.reply[1] + 2) == HB_F_ESTOP);
    send_empty(&dev, HB_ARM, 0);
    parse(&hal, &out);
    CHECK(out.reply[0][1] == HB_FAULT_LATCHED);
    send_config(&dev, 2000, HB_CURRENT, 5.0, 1e4, -INFINITY, INFINITY, 0.0, 4096, 0);  /* faults survive */
    CHECK(dev.faults == HB_F_ESTOP);
    send_empty(&dev, HB_CLEAR_FAULTS, 0);
    send_empty(&dev, HB_ARM, 0);
    parse(&hal, &out);
    CHECK(dev.faults == 0 && out.reply[out.n_replies - 1][1] == HB_OK && dev.state == HB_ARMED);
    /* e-stop before any configuration is latched too, and refused requests say why */
    hb_device_setup s = {"HB-TEST", "T-1", "test", 4096, 128, HB_LOCKSTEP, HB_LINK_SERIAL, 1, 0.5, 20.0, 0};
    hb_device_init(&dev, &s, &hal);
    send_empty(&dev, HB_ARM, 0);
    send_empty(&dev, HB_GET_CONFIG, 0);
    send_config(&dev, 1234, HB_CURRENT, 5.0, 1e4, -INFINITY, INFINITY, 0.0, 4096, 0);
    send_empty(&dev, HB_ESTOP, 0);
    parse(&hal, &out);
    CHECK(out.n_replies == 4 && out.reply[0][1] == HB_NOT_CONFIGURED && out.reply[1][1] == HB_NOT_CONFIGURED &&
          out.reply[2][1] == HB_INVALID_CONFIG && dev.faults == HB_F_ESTOP);
}

/* Over-speed closed form: 2 kHz, W = 2, cpr 1000: v = 2*pi/1000 * dc / 1 ms; 1 count/sample = 6.28 rad/s,
 * 2 counts per window = 12.6 rad/s > 10. The motor is at rest before the first sample. */
static void test_limits_closed_form(void) {
    fresh(HB_LOCKSTEP, 2000, HB_CURRENT, 0.0);
    send_empty(&dev, HB_DISARM, 0);
    send_config(&dev, 2000, HB_CURRENT, 1.0, 10.0, -1.0, 1.0, 0.0, 1000, 0);
    send_empty(&dev, HB_ARM, 0);
    static const int64_t script[] = {0, 1, 1, 2, 3, 4, 6, 8};
    memcpy(hal.script, script, sizeof script);
    hal.n_script = 8;
    hal.measured = 0;
    float zero[8] = {0};
    send_block(&dev, 0, zero, 8, 1, 0);
    hb_device_tick(&dev, 0);
    parse(&hal, &out);
    /* v[k] over counts 0,1,1,2 stays <= 6.28; sample 4 (count 3, two samples after count 1) is 12.6 */
    CHECK(out.n_samples == 5 && out.status[4] == (HB_S_FAULT | HB_S_END));
    CHECK(dev.faults == HB_F_OVER_SPEED && dev.fault_index == 4);
    /* position window: 1.2 rad at cpr 1000 is count 191 */
    send_empty(&dev, HB_CLEAR_FAULTS, 0);
    send_empty(&dev, HB_ARM, 0);
    hal.script[0] = 191;
    hal.n_script = 1;
    hal.measured = 0;
    send_block(&dev, 0, zero, 4, 1, 0);
    hb_device_tick(&dev, 0);
    parse(&hal, &out);
    CHECK(dev.faults == HB_F_POSITION_WINDOW && out.n_samples == 1 && out.counts[0] == 191);
    /* over-current on the command (current mode) and on the measurement */
    send_empty(&dev, HB_CLEAR_FAULTS, 0);
    send_empty(&dev, HB_ARM, 0);
    hal.script[0] = 0;
    float big[3] = {0.5f, 1.5f, 0.0f};
    send_block(&dev, 0, big, 3, 1, 0);
    hb_device_tick(&dev, 0);
    parse(&hal, &out);
    CHECK(dev.faults == HB_F_OVER_CURRENT && out.n_samples == 2 && out.cmd[0] == 0.5f && out.cmd[1] == 0.0f);
    send_empty(&dev, HB_CLEAR_FAULTS, 0);
    send_empty(&dev, HB_ARM, 0);
    hal.gain = 3.0;  /* the amplifier over-shoots: 0.5 A commanded reads 1.5 A at the next sample */
    float fine[3] = {0.5f, 0.5f, 0.5f};
    send_block(&dev, 0, fine, 3, 1, 0);
    hb_device_tick(&dev, 0);
    parse(&hal, &out);
    CHECK(dev.faults == HB_F_OVER_CURRENT && out.n_samples == 2 && out.meas[1] == 1.5f);
}

/* Velocity PI loop against its closed form on a stalled motor (the encoder does not move): v_est = 0,
 * so i[k] = kp*u + ki*u*dt*(k+1) until it saturates at the current limit, where the integral freezes. */
static void test_velocity_loop_closed_form(void) {
    fresh(HB_LOCKSTEP, 1000, HB_VELOCITY, 0.0);
    float u[600];
    for (int i = 0; i < 600; i++) u[i] = 2.0f;
    send_block(&dev, 0, u, 128, 0, 0);
    for (uint32_t b = 1; b < 4; b++) send_block(&dev, b, u, 128, b == 3, 0);
    hb_device_tick(&dev, 0);
    parse(&hal, &out);
    CHECK(out.n_samples == 512);
    double v = 2.0, kp = 0.5, ki = 20.0, dt = 1e-3;
    int ok = 1, saturated = 0;
    for (int k = 0; k < 512; k++) {
        double want = kp * v + ki * v * dt * (k + 1);
        if (want > 5.0) {
            want = 5.0;
            saturated++;
        }
        ok &= fabs(out.cmd[k] - want) <= 1e-6 * fabs(want);
    }
    CHECK(ok && saturated > 0);
    CHECK(out.status[511] == (HB_S_ENABLED | HB_S_END) && dev.state == HB_ARMED);
}

/* ------------------------------------------------------------------ position mode (protocol v2) */

static void send_position_config(hb_device *d, uint32_t rate, double current_limit, uint32_t cpr, double kp,
                                 double ki, double kd, double i_limit, double cutoff, uint8_t flags) {
    hb_config c = {rate, HB_POSITION, current_limit, 1e4, -INFINITY, INFINITY, 0.0, 0.2, cpr, 1.0,
                   kp, ki, kd, i_limit, cutoff, flags};
    uint8_t p[HB_CONFIG_BYTES];
    hb_config_encode(&c, p);
    host_send(d, HB_CONFIG, p, sizeof p, 0);
}

/* Polynomials in z, descending powers: p[0] z^n + ... + p[n]. */
static void poly_mul(const double *a, int na, const double *b, int nb, double *out) {
    for (int i = 0; i <= na + nb; i++) out[i] = 0;
    for (int i = 0; i <= na; i++)
        for (int j = 0; j <= nb; j++) out[i + j] += a[i] * b[j];
}

/* Step response of the position loop on a pure inertia (J 0.0022 kg*m^2, Kt 0.2 N*m/A, 10 kHz), against the
 * closed loop computed here from transfer functions, independently of the core and of the fake plant's
 * state update: plant G(z) = Kt/J * dt^2/2 * (z+1)/(z-1)^2 (a double integrator under zero-order hold);
 * controller C(z) = kp + ki*dt*z/(z-1) + kd*(1-a)/dt*(z-1)/(z-a), a = exp(-2*pi*fc*dt); no delay (sample k
 * is measured, then its current is held over [t_k, t_k+1)). y = CG/(1+CG) r as a difference equation.
 * The encoder has 2^30 counts/rev (quantum 5.9e-9 rad against a 1 mrad step). */
static void test_position_loop_step_closed_form(void) {
    const double J = 0.0022, kt = 0.2, dt = 1e-4, kp = 3000, ki = 3e5, kd = 5, fc = 300, step = 1e-3;
    const uint32_t cpr = 1u << 30;
    fresh(HB_LOCKSTEP, 10000, HB_CURRENT, 0.0);
    send_empty(&dev, HB_DISARM, 0);
    send_position_config(&dev, 10000, 1e3, cpr, kp, ki, kd, 100.0, fc, 0);
    send_empty(&dev, HB_ARM, 0);
    hal.inertia = J;
    hal.kt = kt;
    hal.dt = dt;
    hal.cpr = (double)cpr;
    enum { N = 2048, K0 = 16 };
    static float r[N];
    for (int k = 0; k < N; k++) r[k] = k < K0 ? 0.0f : (float)step;
    for (uint32_t b = 0; b < N / 128; b++) send_block(&dev, b, r + 128 * b, 128, b == N / 128 - 1, 0);
    for (int t = 0; t < 8; t++) hb_device_tick(&dev, 0);  /* lockstep: at most 4 blocks per tick */
    parse(&hal, &out);
    CHECK(out.n_samples == N && dev.faults == 0);

    double a = exp(-2.0 * 3.141592653589793 * fc * dt), g = kt / J * dt * dt / 2.0;
    double z1[2] = {1, -1}, za[2] = {1, -a}, zz[2] = {1, 0}, z11[3], z1a[3], zza[3];
    poly_mul(z1, 1, z1, 1, z11);
    poly_mul(z1, 1, za, 1, z1a);
    poly_mul(zz, 1, za, 1, zza);
    double cn[3], cd[3], gn[2] = {g, g}, *gd = z11, num[4], den[5], cg[5];
    for (int i = 0; i < 3; i++) {
        cn[i] = kp * z1a[i] + ki * dt * zza[i] + kd * (1 - a) / dt * z11[i];
        cd[i] = z1a[i];
    }
    poly_mul(cn, 2, gn, 1, num);  /* degree 3 */
    poly_mul(cd, 2, gd, 2, den);  /* degree 4 */
    for (int i = 0; i < 4; i++) den[i + 1] += num[i];
    for (int i = 0; i < 5; i++) cg[i] = den[i] / den[0];
    static double y[N];
    double worst = 0;
    for (int k = 0; k < N; k++) {
        double acc = 0;
        for (int i = 1; i <= 4 && k - i >= 0; i++) acc += -cg[i] * y[k - i] + num[i - 1] / den[0] * (double)r[k - i];
        y[k] = acc;
        double measured = (double)out.counts[k] * 2.0 * 3.141592653589793 / (double)cpr;
        double e = fabs(measured - y[k]);
        if (e > worst) worst = e;
    }
    /* double: quantisation (half a count, 3e-9 rad) dominates; float: the loop runs in single precision */
    double tol = sizeof(hb_real) == sizeof(float) ? 2e-3 * step : 2e-5 * step;
    printf("position step on a pure inertia: worst |y - closed loop| = %.3g rad (tolerance %.3g rad)\n", worst, tol);
    CHECK(worst <= tol);
    CHECK(fabs(y[N - 1] - step) < 1e-3 * step);  /* the integral removes the static error */
    /* the first current of the step: kp*e + kd*(1-a)*e/dt + ki*dt*e with e = step (float32 on the wire) */
    double e0 = (double)(float)step, i0 = kp * e0 + kd * (1 - a) * e0 / dt + ki * dt * e0;
    CHECK(fabs(out.cmd[K0] - i0) <= 1e-5 * i0 && out.cmd[K0 - 1] == 0.0f);
    hal.inertia = 0;
}

/* Stalled encoder, feed-forward on (two values per sample): e = r constant, D = 0, so
 * i[k] = kp*r + min(ki*r*dt*(k+1), i_limit) + ff[k], clipped at the current limit; the buffer counts
 * samples, an odd number of values is a broken stream, a feed-forward beyond the limit is OVER_CURRENT. */
static void test_position_feedforward_and_integral_limit(void) {
    fresh(HB_LOCKSTEP, 1000, HB_CURRENT, 0.0);
    send_empty(&dev, HB_DISARM, 0);
    const double kp = 1000, ki = 1e4, ilim = 0.25, dt = 1e-3, lim = 5.0;
    send_position_config(&dev, 1000, lim, 4096, kp, ki, 0.0, ilim, 0.0, HB_CFG_FEEDFORWARD);
    send_empty(&dev, HB_ARM, 0);
    parse(&hal, &out);
    CHECK(out.reply[0][1] == HB_OK && out.reply[1][1] == HB_OK && dev.vps == 2 && dev.slots == 2048);
    static float v[2 * 400];
    for (int k = 0; k < 400; k++) {
        v[2 * k] = 1e-3f;
        v[2 * k + 1] = k < 300 ? 0.5f : -3.5f + 0.01f * (float)(k - 300);
    }
    hb_status st;
    send_block(&dev, 0, v, 2 * 128, 0, 0);
    hb_device_status(&dev, 0, &st);
    CHECK(st.free == 2048 - 128 && st.received == 128);
    for (uint32_t b = 1; b < 4; b++) send_block(&dev, b, v + 256 * b, b == 3 ? 2 * 16 : 2 * 128, b == 3, 0);
    hb_device_tick(&dev, 0);
    parse(&hal, &out);
    CHECK(out.n_samples == 400 && dev.faults == 0 && dev.state == HB_ARMED);
    double r = (double)1e-3f;
    int ok = 1, clamped = 0;
    for (int k = 0; k < 400; k++) {
        double integral = ki * r * dt * (k + 1);
        if (integral > ilim) {
            integral = ilim;
            clamped++;
        }
        double want = kp * r + integral + (double)v[2 * k + 1];
        want = want > lim ? lim : want < -lim ? -lim : want;
        ok &= fabs(out.cmd[k] - want) <= 1e-6 * fabs(want) + 1e-7;
    }
    CHECK(ok && clamped > 100);
    /* an odd number of values cannot be whole samples: the stream breaks (BUFFER_UNDERRUN) */
    send_block(&dev, 0, v, 3, 1, 0);
    CHECK(dev.faults == HB_F_BUFFER_UNDERRUN && dev.state == HB_DISARMED);
    parse(&hal, &out);
    /* a feed-forward current beyond the limit trips OVER_CURRENT at its sample */
    send_empty(&dev, HB_CLEAR_FAULTS, 0);
    send_empty(&dev, HB_ARM, 0);
    float over[6] = {0.0f, 0.1f, 0.0f, 6.0f, 0.0f, 0.1f};
    send_block(&dev, 0, over, 6, 1, 0);
    hb_device_tick(&dev, 0);
    parse(&hal, &out);
    CHECK(dev.faults == HB_F_OVER_CURRENT && dev.fault_index == dev.index - 1 && out.n_samples == 2 &&
          out.cmd[1] == 0.0f && out.status[1] == (HB_S_FAULT | HB_S_END));
}

/* The last frame of `type` the device wrote (payload into buf): its version byte, or -1. */
static int last_frame(uint8_t type, uint8_t *buf, size_t *len) {
    int version = -1;
    size_t start = 0;
    for (size_t i = 0; i < hal.tx_len; i++) {
        if (hal.tx[i] != 0) continue;
        long n = hb_cobs_decode(hal.tx + start, i - start, raw);
        start = i + 1;
        if (n >= 6 && raw[1] == type) {
            version = raw[0];
            *len = (size_t)n - 6;
            memcpy(buf, raw + 2, *len);
        }
    }
    hal.tx_len = 0;
    return version;
}

/* Version negotiation: a v1 host (empty GET_IDENTITY, version-1 frames, 65-byte CONFIG) is answered as a v1
 * device, and cannot configure position mode; a v2 host is answered in v2 and reads the position CONFIG;
 * a v1 host then asking for it gets NOT_CONFIGURED (v1 cannot express it). */
static void test_version_negotiation(void) {
    memset(&hal, 0, sizeof hal);
    hb_device_setup s = {"HB-TEST", "T-1", "test", 4096, 128, HB_LOCKSTEP, HB_LINK_SERIAL, 1, 0.5, 20.0, 0};
    hb_device_init(&dev, &s, &hal);
    static uint8_t buf[HB_MAX_FRAME], p[HB_CONFIG_BYTES];
    size_t len = 0;
    host_send(&dev, HB_GET_IDENTITY, NULL, 0, 0);
    CHECK(dev.version == 1 && last_frame(HB_IDENTITY, buf, &len) == 1 && hb_get_u16(buf + len - 8) == 1);
    hb_config c = {1000, HB_VELOCITY, 5.0, 100.0, -INFINITY, INFINITY, 0.5, 0.2, 4096, 1.0, 0, 0, 0, 0, 0, 0};
    hb_config_encode_v1(&c, p);
    host_send(&dev, HB_CONFIG, p, HB_CONFIG_BYTES_V1, 0);
    CHECK(last_frame(HB_REPLY, buf, &len) == 1 && buf[1] == HB_OK && dev.state == HB_DISARMED);
    send_empty(&dev, HB_GET_CONFIG, 0);
    CHECK(last_frame(HB_CONFIG, buf, &len) == 1 && len == HB_CONFIG_BYTES_V1 && memcmp(buf, p, len) == 0);
    c.mode = HB_POSITION;  /* a v1 layout has no gains: position mode is refused */
    hb_config_encode_v1(&c, p);
    host_send(&dev, HB_CONFIG, p, HB_CONFIG_BYTES_V1, 0);
    CHECK(last_frame(HB_REPLY, buf, &len) == 1 && buf[1] == HB_INVALID_CONFIG && dev.cfg.mode == HB_VELOCITY);
    uint8_t v2[2] = {2, 0};
    host_send(&dev, HB_GET_IDENTITY, v2, 2, 0);
    CHECK(dev.version == 2 && last_frame(HB_IDENTITY, buf, &len) == 2 && hb_get_u16(buf + len - 8) == 2);
    send_position_config(&dev, 1000, 5.0, 4096, 100.0, 0.0, 0.0, 0.0, 0.0, 0);
    CHECK(last_frame(HB_REPLY, buf, &len) == 2 && buf[1] == HB_OK && dev.cfg.mode == HB_POSITION);
    send_empty(&dev, HB_GET_CONFIG, 0);
    CHECK(last_frame(HB_CONFIG, buf, &len) == 2 && len == HB_CONFIG_BYTES && buf[4] == HB_POSITION &&
          hb_get_f64(buf + 65) == 100.0);
    host_send(&dev, HB_GET_IDENTITY, NULL, 0, 0);
    send_empty(&dev, HB_GET_CONFIG, 0);
    CHECK(last_frame(HB_REPLY, buf, &len) == 1 && buf[0] == HB_GET_CONFIG && buf[1] == HB_NOT_CONFIGURED);
    /* invalid position configurations: no kp, a derivative cut-off at Nyquist, feed-forward outside mode 2 */
    host_send(&dev, HB_GET_IDENTITY, v2, 2, 0);
    send_position_config(&dev, 1000, 5.0, 4096, 0.0, 0.0, 0.0, 0.0, 0.0, 0);
    CHECK(last_frame(HB_REPLY, buf, &len) == 2 && buf[1] == HB_INVALID_CONFIG);
    send_position_config(&dev, 1000, 5.0, 4096, 100.0, 0.0, 1.0, 0.0, 500.0, 0);
    CHECK(last_frame(HB_REPLY, buf, &len) == 2 && buf[1] == HB_INVALID_CONFIG);
    c.mode = HB_CURRENT;
    c.flags = HB_CFG_FEEDFORWARD;
    hb_config_encode(&c, p);
    host_send(&dev, HB_CONFIG, p, HB_CONFIG_BYTES, 0);
    CHECK(last_frame(HB_REPLY, buf, &len) == 2 && buf[1] == HB_INVALID_CONFIG);
}

/* Protocol v3: a device whose setup names a temperature sensor says so in IDENTITY and puts the HAL's
 * reading, taken when the block is sent, in every SAMPLES header; without the sensor the header carries NaN;
 * a v2 host gets the 27-byte header and an IDENTITY without the sensors byte. */
static void test_v3_temperature(void) {
    static uint8_t buf[HB_MAX_FRAME];
    size_t len = 0;
    for (int sensors = 0; sensors <= 1; sensors++) {
        memset(&hal, 0, sizeof hal);
        hal.gain = 1.0;
        hal.temperature = 30.0;
        hb_device_setup s = {"HB-TEST", "T-1", "test", 4096, 16, HB_LOCKSTEP, HB_LINK_SERIAL, 1, 0.5, 20.0,
                             (uint8_t)(sensors ? HB_SENSOR_TEMPERATURE : 0)};
        hb_device_init(&dev, &s, &hal);
        uint8_t v3[2] = {3, 0};
        host_send(&dev, HB_GET_IDENTITY, v3, 2, 0);
        CHECK(dev.version == 3 && last_frame(HB_IDENTITY, buf, &len) == 3);
        CHECK(buf[len - 1] == sensors && hb_get_u16(buf + len - 9) == 3);
        send_config(&dev, 1000, HB_CURRENT, 5.0, 1e4, -INFINITY, INFINITY, 0.0, 4096, 0);
        send_empty(&dev, HB_ARM, 0);
        send_block(&dev, 0, ones, 16, 0, 0);  /* setpoint blocks of at most max_block too */
        send_block(&dev, 1, ones, 16, 0, 0);
        send_block(&dev, 2, ones, 8, 1, 0);
        for (int t = 0; t < 8; t++) hb_device_tick(&dev, 1000000);  /* lockstep: at most 4 blocks per tick */
        parse(&hal, &out);
        CHECK(out.n_samples == 40 && out.n_blocks == 3);  /* 16 + 16 + 8 samples */
        for (size_t i = 0; i < out.n_blocks; i++) {
            /* the fake reading grows 0.25 degC per sample applied: read when the block goes out, after
             * its last sample (first + n - 1) and at most one more (a full block leaves with the next one) */
            size_t n = i + 1 < out.n_blocks ? 16 : 8;
            double after = 30.0 + 0.25 * (double)(out.first[i] + n), got = out.block_temperature[i];
            CHECK(sensors ? got == after || got == after + 0.25 : isnan(out.block_temperature[i]));
        }
        CHECK(hal.temperature_reads == (sensors ? 3u : 0u));  /* no sensor: the HAL is not asked */
    }
    uint8_t v2[2] = {2, 0};  /* a v2 host on the sensing device: the v2 layouts */
    host_send(&dev, HB_GET_IDENTITY, v2, 2, 0);
    CHECK(dev.version == 2 && last_frame(HB_IDENTITY, buf, &len) == 2 && hb_get_u16(buf + len - 8) == 2);
    send_empty(&dev, HB_CLEAR_FAULTS, 0);
    send_empty(&dev, HB_ARM, 0);
    send_block(&dev, 0, ones, 10, 1, 2000000);
    for (int t = 0; t < 4; t++) hb_device_tick(&dev, 3000000);
    parse(&hal, &out);
    CHECK(out.n_samples == 10 && out.n_blocks == 1 && isnan(out.block_temperature[0]));
}

static void can_sink(void *ctx, uint16_t id, const uint8_t *data, uint8_t len) {
    hb_device *d = ctx;
    /* host-to-device: flip the direction bit of a frame the device would send */
    hb_device_rx_can(d, (uint16_t)(id & ~0x10u), data, len, 0);
}

/* CAN: a CONFIG in 10 classic segments reaches the device; its REPLY comes back in one frame whose id
 * carries type 0x0B, direction 1, node 3. A lost segment drops that message only (counted). */
static void test_can_mapping(void) {
    memset(&hal, 0, sizeof hal);
    hb_device_setup s = {"HB-TEST", "T-1", "test", 4096, 60, HB_LOCKSTEP, HB_LINK_CAN, 3, 0.5, 20.0, 0};
    hb_device_init(&dev, &s, &hal);
    hb_config c = {1000, HB_CURRENT, 5.0, 100.0, -INFINITY, INFINITY, 0.5, 0.2, 4096, 1.0, 0, 0, 0, 0, 0, 0};
    uint8_t p[HB_CONFIG_BYTES];
    hb_config_encode_v1(&c, p);  /* a v1 host's CONFIG */
    CHECK(hb_can_send(HB_CONFIG, p, HB_CONFIG_BYTES_V1, 3, 0, can_sink, &dev) == 10);
    CHECK(dev.state == HB_DISARMED && hal.can_frames == 1);
    CHECK(hal.can_id[0] == (HB_REPLY << 5 | 1 << 4 | 3) && hal.can_len[0] == 7 && hal.can_data[0][0] == 0x80);
    CHECK(hal.can_data[0][1] == 4 && hal.can_data[0][3] == HB_CONFIG && hal.can_data[0][4] == HB_OK);
    uint8_t seg0[8] = {0x00, HB_CONFIG_BYTES_V1, 0, 1, 2, 3, 4, 5};
    hb_device_rx_can(&dev, (uint16_t)(HB_CONFIG << 5 | 3), seg0, 8, 0);
    uint8_t seg2[8] = {0x02};
    hb_device_rx_can(&dev, (uint16_t)(HB_CONFIG << 5 | 3), seg2, 8, 0);
    CHECK(dev.can.dropped_frames == 1);
    uint8_t hb[7] = {0x80, 4, 0, 1, 2, 3, 4};
    hb_device_rx_can(&dev, (uint16_t)(HB_HEARTBEAT << 5 | 3), hb, 7, 0);
    CHECK(hal.can_frames > 1 && hal.can_id[1] == (HB_STATUS << 5 | 1 << 4 | 3));
    hb_device_rx_can(&dev, (uint16_t)(HB_HEARTBEAT << 5 | 4), hb, 7, 0);  /* another node: ignored */
    CHECK(dev.rx_frames == 2);
    /* a v2 CONFIG (106 bytes, 16 classic segments) is reassembled too */
    hb_config cp = {1000, HB_POSITION, 5.0, 100.0, -INFINITY, INFINITY, 0.5, 0.2, 4096, 1.0,
                    3000.0, 3e5, 5.0, 5.0, 300.0, HB_CFG_FEEDFORWARD};
    hb_config_encode(&cp, p);
    hal.can_frames = 0;
    CHECK(hb_can_send(HB_CONFIG, p, HB_CONFIG_BYTES, 3, 0, can_sink, &dev) == 16);
    CHECK(hal.can_frames == 1 && hal.can_data[0][3] == HB_CONFIG && hal.can_data[0][4] == HB_OK &&
          dev.cfg.mode == HB_POSITION && dev.cfg.position_ki == 3e5 && dev.vps == 2);
}

int main(int argc, char **argv) {
    if (argc != 2) {
        fprintf(stderr, "usage: test_core GOLDEN_DIR\n");
        return 2;
    }
    for (int i = 0; i < 4096; i++) ones[i] = 1.0f;
    test_crc32_and_cobs();
    test_golden_frames(argv[1]);
    test_realtime_watchdog_index();
    test_watchdog_at_a_block_boundary();
    test_lockstep_watchdog_with_empty_buffer();
    test_underrun_gap_and_overflow();
    test_estop_disarm_and_latching();
    test_limits_closed_form();
    test_velocity_loop_closed_form();
    test_position_loop_step_closed_form();
    test_position_feedforward_and_integral_limit();
    test_version_negotiation();
    test_v3_temperature();
    test_can_mapping();
    printf("%d checks, %d failed\n", checks, failures);
    return failures ? 1 : 0;
}
