"""cffi build script for the C plant (``firmware_sim._plant``); setup.py names it in ``cffi_modules``."""

from pathlib import Path

from cffi import FFI

HERE = Path(__file__).resolve().parent

CDEF = """
#define HB_MAX_ELEMENTS 1024
#define HB_MAX_DELAY 4096
#define HB_MODE_CURRENT 0
#define HB_MODE_VELOCITY 1

typedef struct {
    int n_elements;
    const double *ms_stiffness;
    const double *ms_delta;
    double inertia;
    double spring;
    double viscous_pos;
    double viscous_neg;
    double coulomb_pos;
    double coulomb_neg;
    double stribeck_excess;
    double stribeck_velocity;
    double torque_constant;
    double torque_constant_error;
    double torque_offset;
    double torque_drift;
    int n_cogging;
    const double *cogging_order;
    const double *cogging_amplitude;
    const double *cogging_phase;
    int delay_samples;
    double current_lag;
    int64_t counts_per_rev;
    double noise_current;
    double noise_position;
    double velocity_kp;
    double velocity_ki;
    double current_limit;
    int n_restoring;
    const double *restoring_x;
    const double *restoring_f;
    int n_damping;
    const double *damping_v;
    const double *damping_f;
} hb_params;

typedef struct {
    double theta;
    double omega;
    double time;
    double current;
    double prev_position;
    double pi_integral;
    double coulomb_force;
    double ms_offset;
    double spare_normal;
    uint64_t rng[4];
    int32_t has_spare;
    int32_t has_prev;
    int32_t delay_pos;
    int32_t n_elements;
    double delay_buf[4096];
    double deflection[1024];
} hb_state;

typedef struct {
    double *theta;
    double *omega;
    double *friction;
    double *current_cmd;
    double *current_meas;
    double *torque;
    double *position_meas;
    int64_t *counts;
} hb_outputs;

void hb_state_init(hb_state *s, const hb_params *p, double theta0, double omega0, uint64_t seed);
int hb_run(const hb_params *p, hb_state *s, const double *u, int64_t n, double dt, int substeps,
           int mode, hb_outputs *out);
void hb_stop_operator(const double *x, int64_t n, const double *deltas, int m, double *state,
                      double *out);
void hb_normals(hb_state *s, double *out, int64_t n);
void hb_deflections(const hb_params *p, const hb_state *s, double *out);
"""

ffibuilder = FFI()
ffibuilder.cdef(CDEF)
ffibuilder.set_source(
    "firmware_sim._plant",
    '#include "plant.h"',
    sources=[str(Path("firmware_sim") / "plant.c")],
    include_dirs=[str(HERE)],
    extra_compile_args=["-O3", "-std=c99", "-ffp-contract=off", "-fno-fast-math"],
    libraries=["m"],
)

if __name__ == "__main__":
    ffibuilder.compile(verbose=True)
