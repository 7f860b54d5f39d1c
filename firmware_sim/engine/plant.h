/* hilbench plant: a DC motor (or mass) with Maxwell-slip friction, sampled as a device sees it.
 *
 * Equations, integration scheme and sampling convention: docs/plant.md.
 * All quantities are SI: rad, rad/s, N*m, A, s (or m, m/s, N for a linear axis).
 */
#ifndef HILBENCH_PLANT_H
#define HILBENCH_PLANT_H

#include <stdint.h>

#define HB_MAX_ELEMENTS 1024
#define HB_MAX_DELAY 4096
#define HB_MAX_GMS 256
#define HB_MAX_STACK 1024
#define HB_MODE_CURRENT 0
#define HB_MODE_VELOCITY 1
#define HB_MODE_POSITION 2

typedef struct {
    int n_elements;              /* Maxwell-slip elements, 0..HB_MAX_ELEMENTS */
    const double *ms_stiffness;  /* k_i, N*m/rad */
    const double *ms_delta;      /* slip displacement Delta_i = W_i / k_i, rad */
    double inertia;              /* J, kg*m^2 */
    double spring;               /* linear spring, N*m/rad */
    double viscous_pos;          /* b for omega >= 0, N*m*s/rad */
    double viscous_neg;          /* b for omega < 0 */
    double coulomb_pos;          /* F_c for motion in + direction, N*m */
    double coulomb_neg;          /* F_c for motion in - direction, N*m */
    double stribeck_excess;      /* F_s - F_c, N*m */
    double stribeck_velocity;    /* v_s, rad/s (0: no Stribeck) */
    double torque_constant;      /* nominal k_t, N*m/A */
    double torque_constant_error;/* relative error of the true k_t */
    double torque_offset;        /* N*m */
    double torque_drift;         /* N*m/s */
    int n_cogging;
    const double *cogging_order; /* cycles per revolution */
    const double *cogging_amplitude; /* N*m */
    const double *cogging_phase; /* rad */
    int delay_samples;           /* 0..HB_MAX_DELAY */
    double current_lag;          /* first-order time constant, s (0: off) */
    int64_t counts_per_rev;      /* 0: ideal encoder */
    double noise_current;        /* A rms */
    double noise_position;       /* rad rms */
    double velocity_kp;          /* A/(rad/s) */
    double velocity_ki;          /* A/rad */
    double current_limit;        /* A */
    int n_restoring;             /* tabulated odd restoring force F_k(x), x >= 0 grid */
    const double *restoring_x;
    const double *restoring_f;
    int n_damping;               /* tabulated odd damping force F_d(v), v >= 0 grid */
    const double *damping_v;
    const double *damping_f;
    /* LuGre: F = s0*z + s1*dz/dt + s2*omega, dz/dt = omega - s0*|omega|*z/g(omega),
     * g(omega) = Fc + (Fs - Fc)*exp(-|omega/vs|^delta). lugre = 0: off. */
    int lugre;
    double lg_sigma0;            /* N*m/rad */
    double lg_sigma1;            /* N*m*s/rad */
    double lg_sigma2;            /* N*m*s/rad */
    double lg_coulomb, lg_static;/* Fc, Fs, N*m */
    double lg_stribeck_velocity; /* vs, rad/s (0: g = Fc) */
    double lg_exponent;          /* delta, > 0 */
    /* Generalized Maxwell-slip: F = sum F_i + s2*omega; element i sticks (dF_i/dt = k_i*omega) until
     * |F_i| reaches alpha_i*s(omega), then slips with dF_i/dt = C*(sgn(omega) - F_i/(alpha_i*s(omega)))
     * until the motion reverses. s(omega) = Fc + (Fs - Fc)*exp(-|omega/vs|^delta). gms_n = 0: off. */
    int gms_n;                   /* 0..HB_MAX_GMS */
    const double *gms_k;         /* k_i, N*m/rad */
    const double *gms_alpha;     /* alpha_i, dimensionless */
    double gms_attraction;       /* C, N*m/s; +inf: the force follows alpha_i*s(omega) at once */
    double gms_coulomb, gms_static, gms_stribeck_velocity, gms_exponent, gms_sigma2;
    /* Continuous virgin-curve hysteresis phi(x) = h*(1 - (d/(d+|x|))^2)*sgn(x), Masing branches and
     * wiping-out over a stack of at most hy_stack reversal points. hy_stack = 0: off. */
    int hy_stack;                /* 0..HB_MAX_STACK */
    double hy_h;                 /* N*m */
    double hy_d;                 /* rad */
} hb_params;

typedef struct {
    double theta;        /* rad */
    double omega;        /* rad/s */
    double time;         /* s since the state was initialised */
    double current;      /* actual motor current (after delay and lag), A */
    double prev_position;/* previous measured position, for the velocity estimate, rad */
    double pi_integral;  /* integral of the velocity error, rad */
    double coulomb_force;/* Coulomb/Stribeck force of the last sub-step, N*m */
    double ms_offset;    /* lazy stop operator: displacement since the last commit, rad */
    double spare_normal; /* Box-Muller second deviate */
    uint64_t rng[4];     /* xoshiro256** */
    int32_t has_spare;
    int32_t has_prev;
    int32_t delay_pos;
    int32_t n_elements;
    double delay_buf[HB_MAX_DELAY];
    double deflection[HB_MAX_ELEMENTS];  /* Maxwell-slip deflections at the last commit, rad */
    double lg_z;         /* LuGre bristle deflection, rad */
    double hy_x;         /* hysteresis path coordinate (displacement since the start), rad */
    int32_t hy_dir;      /* direction of the current branch: +1, -1, 0 before the first motion */
    int32_t hy_m;        /* reversal points on the stack */
    int32_t hy_depth_max;/* most reversal points ever held */
    int32_t hy_dropped;  /* reversals forgotten because the stack was full */
    double hy_xs[HB_MAX_STACK];  /* reversal points, rad */
    double hy_fs[HB_MAX_STACK];  /* force at each reversal point, N*m */
    double gms_f[HB_MAX_GMS];    /* GMS element forces, N*m */
    int32_t gms_slip[HB_MAX_GMS];/* 0: sticking; +1/-1: slipping in that direction */
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

/* Run n samples of input u (A in current mode, rad/s in velocity mode), each held for dt and
 * integrated in `substeps` RK4 sub-steps. Returns 0, -1 if the state became non-finite, or -2 for
 * HB_MODE_POSITION (run by hb_run_position, with its loop). */
int hb_run(const hb_params *p, hb_state *s, const double *u, int64_t n, double dt, int substeps,
           int mode, hb_outputs *out);

/* The position loop of HB_MODE_POSITION (moteus's position PID), closed at every sample on the measured
 * position pos: e = target - pos; I = clip(I + ki*e*dt, +-ilimit); torque = kp*e + I + kd*(velocity - v) +
 * feedforward, clipped to +-torque_limit, then current = torque/torque_constant (nominal), clipped to
 * +-current_limit. v is the encoder's velocity estimate: with pll_hz > 0 a critically damped second-order
 * tracking loop on pos of natural frequency pll_hz (w = 2*pi*pll_hz: x += v*dt; e = pos - x; x += 2w*dt*e;
 * v += w^2*dt*e), else the backward difference (pos[k] - pos[k-1])/dt. The estimate and I are kept here between
 * calls; both restart (from the measurement, v from the backward difference, I = 0) when the plant ran
 * otherwise since (est_time != the plant's time). A NaN target turns the proportional and integral terms off
 * (I is held). */
typedef struct {
    double kp;                   /* N*m/rad */
    double ki;                   /* N*m/(rad*s) */
    double ilimit;               /* N*m, >= 0: the integral term's bound */
    double kd;                   /* N*m*s/rad */
    double velocity;             /* velocity command, rad/s */
    double feedforward;          /* N*m */
    double torque_limit;         /* N*m, > 0 (inf: none) */
    double pll_hz;               /* natural frequency of the velocity estimator, Hz (0: backward difference) */
    double integral;             /* the loop's state: the integral term, N*m, */
    double est_position;         /* the velocity estimator's: rad, */
    double est_velocity;         /* rad/s, */
    double est_time;             /* and the plant time they stand at, s */
    int32_t est_valid;
} hb_position_loop;

/* hb_run in HB_MODE_POSITION: target[k] (rad, or NaN) held for dt, the loop closed at every sample. */
int hb_run_position(const hb_params *p, hb_state *s, hb_position_loop *loop, const double *target,
                    int64_t n, double dt, int substeps, hb_outputs *out);

/* hb_run's per-call set-up (the Maxwell-slip cache: O(N) in the elements, more than the sample's RK4 step at 16
 * elements) kept from one call to the next, for a caller that steps the plant a sample at a time (the device's
 * plant HAL). The results are hb_run's, bit for bit: a run split into calls is exact. Set `valid` to 0 whenever
 * the parameters change or the state changes other than through hb_run_cached. */
#define HB_RUN_CACHE_WORDS 160
typedef struct {
    int32_t valid;
    double words[HB_RUN_CACHE_WORDS];
} hb_run_cache;

int hb_run_cached(const hb_params *p, hb_state *s, hb_run_cache *cache, const double *u, int64_t n, double dt,
                  int substeps, int mode, hb_outputs *out);

/* Friction along an imposed motion: position x[k] (rad) and velocity v[k] (rad/s), the path linear between
 * samples. out[k] is the friction at sample k (as the `friction` output of hb_run, with the Coulomb force
 * sgn(v)*level and 0 at v = 0). The state's theta/omega follow the path. */
void hb_friction_path(const hb_params *p, hb_state *s, const double *x, const double *v, int64_t n, double dt,
                      double *out);

/* Stop (play) operator for m thresholds over a path x[0..n): out is n*m, row-major.
 * state[j] is the deflection at x[0] on entry and at x[n-1] on exit. */
void hb_stop_operator(const double *x, int64_t n, const double *deltas, int m, double *state,
                      double *out);

/* Current deflections delta_i = clip(e_i + offset) of the n elements, rad. */
void hb_deflections(const hb_params *p, const hb_state *s, double *out);

/* Standard normal deviates from the plant's generator (for tests of the generator). */
void hb_normals(hb_state *s, double *out, int64_t n);

#endif
