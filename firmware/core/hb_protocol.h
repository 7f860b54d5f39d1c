/* hilbench protocol v3 (and v1, v2 hosts), device side: constants, wire structs, framing and the message codec.
 *
 * Byte layouts: docs/protocol.md. Everything is little-endian on the wire and is assembled byte by byte,
 * so the code does not depend on the target's endianness or struct packing.
 */
#ifndef HB_PROTOCOL_H
#define HB_PROTOCOL_H

#include <stddef.h>
#include <stdint.h>

#define HB_PROTOCOL_VERSION 3       /* the newest version this core speaks (v3: sensors, temperature) */
#define HB_PROTOCOL_VERSION_MIN 1   /* the oldest version it still serves (a v1 host) */
#define HB_MAX_FRAME 8192            /* decoded frame limit: version + type + payload + crc32, bytes */
#define HB_MAX_PAYLOAD (HB_MAX_FRAME - 6)
#define HB_COBS_MAX(n) ((n) + (n) / 254 + 2) /* encoded size of n bytes, delimiter included */

enum hb_msg_type {
    HB_ESTOP = 0x01, HB_DISARM = 0x02, HB_ARM = 0x03, HB_CLEAR_FAULTS = 0x04, HB_CONFIG = 0x05,
    HB_GET_CONFIG = 0x06, HB_GET_IDENTITY = 0x07, HB_IDENTITY = 0x08, HB_HEARTBEAT = 0x09,
    HB_STATUS = 0x0A, HB_REPLY = 0x0B, HB_SETPOINTS = 0x0C, HB_SAMPLES = 0x0D
};
enum hb_state { HB_UNCONFIGURED = 0, HB_DISARMED = 1, HB_ARMED = 2, HB_STREAMING = 3 };
enum hb_fault {
    HB_F_OVER_CURRENT = 0x01, HB_F_OVER_SPEED = 0x02, HB_F_POSITION_WINDOW = 0x04, HB_F_WATCHDOG = 0x08,
    HB_F_BUFFER_UNDERRUN = 0x10, HB_F_ESTOP = 0x20
};
enum hb_sample_status { HB_S_ENABLED = 0x01, HB_S_FAULT = 0x02, HB_S_END = 0x04 };
enum hb_result { HB_OK = 0, HB_FAULT_LATCHED = 1, HB_NOT_CONFIGURED = 2, HB_INVALID_CONFIG = 3, HB_BAD_STATE = 4 };
enum hb_mode { HB_CURRENT = 0, HB_VELOCITY = 1, HB_POSITION = 2 };
enum hb_config_flags { HB_CFG_FEEDFORWARD = 0x01 };
enum hb_sensors { HB_SENSOR_TEMPERATURE = 0x01 };  /* IDENTITY v3: what the SAMPLES header reports */

#define HB_CONFIG_BYTES_V1 65          /* protocol v1 layout: no position loop */
#define HB_CONFIG_BYTES 106            /* protocol v2 layout: v1 + position gains + flags */
#define HB_STATUS_BYTES 63
#define HB_SAMPLES_HEADER_BYTES 27     /* v1, v2 layout */
#define HB_SAMPLES_HEADER_BYTES_V3 31  /* v3: + temperature f32 */
#define HB_SAMPLE_BYTES 14

/* CONFIG as on the wire (f64 values are kept as sent, so GET_CONFIG echoes them exactly). */
typedef struct {
    uint32_t sample_rate;     /* Hz */
    uint8_t mode;             /* enum hb_mode */
    double current_limit;     /* A */
    double velocity_limit;    /* rad/s */
    double position_min;      /* rad, may be -inf */
    double position_max;      /* rad, may be +inf */
    double watchdog_timeout;  /* s, 0 = off */
    double torque_constant;   /* N*m/A */
    uint32_t counts_per_rev;
    double ratio;
    /* protocol v2: position loop (mode 2); zero in a v1 CONFIG */
    double position_kp;       /* A/rad */
    double position_ki;       /* A/(rad*s) */
    double position_kd;       /* A*s/rad */
    double position_i_limit;  /* A, bound of the integral term */
    double position_d_cutoff; /* Hz, first-order low-pass of the derivative term, 0 = unfiltered */
    uint8_t flags;            /* enum hb_config_flags */
} hb_config;

typedef struct {
    uint32_t token;
    uint8_t state;
    uint16_t faults;
    uint64_t index, received, fault_index, fault_silence;
    uint32_t free;
    float current_applied;    /* A */
    uint32_t crc_errors, dropped_frames, rx_frames, tx_frames;
} hb_status;

typedef struct {
    uint32_t seq, free;
    uint64_t first_index, received;
    uint16_t faults;
    uint8_t state;
    float temperature;        /* v3: winding temperature, degC; NaN when the device has no sensor */
} hb_samples_header;

/* A decoded host message. For SETPOINTS, `values` points into the payload (n little-endian f32). */
typedef struct {
    uint8_t type;
    uint32_t token;           /* HEARTBEAT */
    uint16_t host_version;    /* GET_IDENTITY: the protocol the host speaks (1 = empty payload) */
    uint8_t config_version;   /* CONFIG: layout received, 1 or 2 */
    uint32_t seq;             /* SETPOINTS */
    uint8_t end;              /* SETPOINTS */
    uint32_t n_values;        /* SETPOINTS */
    const uint8_t *values;    /* SETPOINTS */
    hb_config config;         /* CONFIG */
} hb_msg;

/* ---- little-endian fields ---- */
void hb_put_u16(uint8_t *p, uint16_t v);
void hb_put_u32(uint8_t *p, uint32_t v);
void hb_put_u64(uint8_t *p, uint64_t v);
void hb_put_f32(uint8_t *p, float v);
void hb_put_f64(uint8_t *p, double v);
uint16_t hb_get_u16(const uint8_t *p);
uint32_t hb_get_u32(const uint8_t *p);
uint64_t hb_get_u64(const uint8_t *p);
float hb_get_f32(const uint8_t *p);
double hb_get_f64(const uint8_t *p);

/* ---- CRC-32 (IEEE 802.3, reflected, init and final xor 0xFFFFFFFF: zlib.crc32) ---- */
uint32_t hb_crc32(uint32_t crc, const uint8_t *data, size_t n);

/* ---- COBS ---- */
/* Encode n bytes into out (HB_COBS_MAX(n) - 1 bytes suffice); no delimiter. Returns the encoded length. */
size_t hb_cobs_encode(const uint8_t *in, size_t n, uint8_t *out);
/* Decode n bytes (no delimiter) into out (n bytes suffice). Returns the length, or -1 for bad COBS. */
long hb_cobs_decode(const uint8_t *in, size_t n, uint8_t *out);

/* Serial frame: COBS(version | type | payload | crc32) 0x00 into out. Returns the bytes written, or 0 if
 * the payload is too long. out needs HB_COBS_MAX(n + 6) bytes. */
size_t hb_frame_encode(uint8_t type, const uint8_t *payload, size_t n, uint8_t *out);
/* The same with the frame's version byte given (the device answers a v1 host with version-1 frames). */
size_t hb_frame_encode_version(uint8_t version, uint8_t type, const uint8_t *payload, size_t n, uint8_t *out);

/* Streaming frame decoder: feed bytes; complete valid frames come back one at a time. */
typedef struct {
    uint32_t len;             /* bytes of the current encoded frame */
    uint8_t discarding;       /* inside an oversize frame: drop until the next 0x00 */
    uint32_t crc_errors;      /* frames rejected: COBS, CRC, version, payload, oversize */
    uint32_t frames;          /* valid frames */
    uint8_t version;          /* version byte of the last valid frame */
    uint8_t enc[HB_COBS_MAX(HB_MAX_FRAME)];
    uint8_t raw[HB_COBS_MAX(HB_MAX_FRAME)];
} hb_frame_decoder;

void hb_frame_decoder_init(hb_frame_decoder *d);
/* Consume bytes from *data until one frame is complete. Returns 1 with the frame's type and payload
 * (pointing into d->raw, valid until the next call) or 0 when the bytes ran out. */
int hb_frame_decoder_next(hb_frame_decoder *d, const uint8_t **data, size_t *n, uint8_t *type,
                          const uint8_t **payload, size_t *len);

/* ---- messages ---- */
/* Decode a message addressed to the device; device-to-host types are checked for their layout and
 * returned as is. Returns 0, or -1 for an unknown type or a payload that does not fit its type. */
int hb_msg_decode(uint8_t type, const uint8_t *payload, size_t n, hb_msg *msg);
void hb_config_encode(const hb_config *c, uint8_t *out);            /* HB_CONFIG_BYTES (v2 layout) */
void hb_config_encode_v1(const hb_config *c, uint8_t *out);         /* HB_CONFIG_BYTES_V1 (v1 layout) */
/* Decode a v1 (HB_CONFIG_BYTES_V1) or v2 (HB_CONFIG_BYTES) layout; v1 leaves the position fields zero. */
void hb_config_decode(const uint8_t *in, size_t n, hb_config *c);
int hb_config_valid(const hb_config *c);                            /* 1 = valid */
void hb_status_encode(const hb_status *s, uint8_t *out);            /* HB_STATUS_BYTES */
void hb_reply_encode(uint8_t request, uint8_t result, uint16_t faults, uint8_t *out); /* 4 bytes */
/* IDENTITY; strings are cut at 255 bytes. Returns the payload length. out needs 3*256 + 8 bytes. */
size_t hb_identity_encode(const char *model, const char *serial, const char *firmware, uint32_t capacity,
                          uint16_t max_block, uint8_t *out);
/* The same reporting protocol `version` (the one agreed with the host). */
size_t hb_identity_encode_version(const char *model, const char *serial, const char *firmware, uint32_t capacity,
                                  uint16_t max_block, uint16_t version, uint8_t *out);
/* v3 and later: the IDENTITY ends with the sensors byte (enum hb_sensors). */
size_t hb_identity_encode_sensors(const char *model, const char *serial, const char *firmware, uint32_t capacity,
                                  uint16_t max_block, uint16_t version, uint8_t sensors, uint8_t *out);
void hb_samples_header_encode(const hb_samples_header *h, uint8_t *out); /* HB_SAMPLES_HEADER_BYTES */
/* The header in the layout of `version`; returns its length (HB_SAMPLES_HEADER_BYTES_V3 from v3). */
size_t hb_samples_header_encode_version(const hb_samples_header *h, uint8_t version, uint8_t *out);

#endif
