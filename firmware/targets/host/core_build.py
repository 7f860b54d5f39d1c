"""cffi build script of the host target (``hilbench.firmware_sim.devices._fwcore``): the firmware core
(firmware/core/*.c), the host HAL and the C plant it drives. setup.py names it in ``cffi_modules``."""

import importlib.util
from pathlib import Path

from cffi import FFI

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[2]
CORE = ROOT / "firmware" / "core"
PLANT_DIR = ROOT / "firmware_sim" / "engine"


def _plant_cdef() -> str:
    """plant.h's declarations, through the plant's own build script (one parser of that header)."""
    spec = importlib.util.spec_from_file_location("_plant_build", PLANT_DIR / "plant_build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.CDEF


CDEF = _plant_cdef() + """
typedef struct {
    const char *model, *serial, *firmware;
    uint32_t capacity;
    uint16_t max_block;
    uint8_t pacing;
    uint8_t link;
    uint8_t can_node;
    double velocity_kp;
    double velocity_ki;
    uint8_t sensors;
} hb_device_setup;

typedef struct {
    uint32_t token;
    uint8_t state;
    uint16_t faults;
    uint64_t index, received, fault_index, fault_silence;
    uint32_t free;
    float current_applied;
    uint32_t crc_errors, dropped_frames, rx_frames, tx_frames;
} hb_status;

typedef struct {
    uint8_t state;
    uint16_t faults;
    uint64_t index;
    uint32_t count;
    uint32_t identity_requests;
    ...;
} hb_device;

typedef struct {
    uint16_t id;
    uint8_t len;
    uint8_t data[64];
} hb_host_can_frame;

typedef struct {
    int on;
    double winding_resistance, thermal_resistance, thermal_time_constant, reference_temperature;
    double level_temperature_coefficient, viscous_temperature_coefficient;
    double wear_rate, wear_step, wear_step_distance, block;
    double ambient, temperature, distance;
} hb_drift;

typedef struct {
    hb_params base;
    hb_params params;
    int substeps_by_rate[5];
    uint64_t seed;
    int plant_failed;
    hb_drift drift;
    ...;
} hb_plant_hal;

void hb_plant_hal_rest(hb_plant_hal *h, double seconds);
double hb_drift_level(const hb_drift *d);
double hb_drift_viscous(const hb_drift *d);

typedef struct {
    hb_plant_hal sim;
    size_t tx_len;
    uint32_t tx_dropped;
    uint32_t can_n;
    hb_device device;
    uint8_t tx[...];
    hb_host_can_frame can[...];
    ...;
} hb_host;

void hb_host_init(hb_host *h, const hb_device_setup *setup);
void hb_device_rx_bytes(hb_device *d, const uint8_t *data, size_t n, uint64_t now_us);
void hb_device_rx_can(hb_device *d, uint16_t id, const uint8_t *data, uint8_t len, uint64_t now_us);
void hb_device_handle(hb_device *d, uint8_t type, const uint8_t *payload, size_t n, uint64_t now_us);
void hb_device_tick(hb_device *d, uint64_t now_us);
int hb_device_busy(const hb_device *d);
void hb_device_status(const hb_device *d, uint32_t token, hb_status *s);
void hb_device_count_dropped(hb_device *d, uint32_t frames);

uint32_t hb_crc32(uint32_t crc, const uint8_t *data, size_t n);
size_t hb_cobs_encode(const uint8_t *in, size_t n, uint8_t *out);
long hb_cobs_decode(const uint8_t *in, size_t n, uint8_t *out);
size_t hb_frame_encode(uint8_t type, const uint8_t *payload, size_t n, uint8_t *out);
"""

SOURCES = [*(f"firmware/core/{name}" for name in ("hb_codec.c", "hb_can.c", "hb_device.c")),
           "firmware/targets/host/hb_host.c", "firmware/targets/plant/hb_plant_hal.c", "firmware_sim/engine/plant.c"]

ffibuilder = FFI()
ffibuilder.cdef(CDEF)
ffibuilder.set_source(
    "hilbench.firmware_sim.devices._fwcore",
    '#include "hb_host.h"',
    sources=SOURCES,
    include_dirs=[str(CORE), str(HERE), str(HERE.parent / "plant"), str(PLANT_DIR)],
    define_macros=[("HB_BUFFER_CAPACITY", "1048576")],  # the simulator's buffer_capacity may go up to 2**20
    extra_compile_args=["-O2", "-std=c99", "-ffp-contract=off", "-fno-fast-math", "-Wall", "-Wextra"],
    libraries=["m"],
)

if __name__ == "__main__":
    ffibuilder.compile(verbose=True)
