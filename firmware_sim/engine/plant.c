/* hilbench plant. See plant.h and docs/plant.md.
 *
 * Built with -ffp-contract=off so that the pure-Python oracle (firmware_sim/reference.py), which performs
 * the same operations in the same order, agrees to rounding.
 */
#include <math.h>
#include <string.h>

#include "plant.h"

#define HB_TWO_PI 6.283185307179586

/* ---- random numbers: splitmix64 seeding, xoshiro256**, Box-Muller ---- */

static uint64_t splitmix64(uint64_t *x) {
    uint64_t z = (*x += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

static inline uint64_t rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

static uint64_t xoshiro_next(uint64_t *s) {
    uint64_t result = rotl(s[1] * 5, 7) * 9;
    uint64_t t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = rotl(s[3], 45);
    return result;
}

static double normal(hb_state *s) {
    if (s->has_spare) {
        s->has_spare = 0;
        return s->spare_normal;
    }
    /* u1 in (0, 1], u2 in [0, 1) */
    double u1 = (double)((xoshiro_next(s->rng) >> 11) + 1) * 0x1.0p-53;
    double u2 = (double)(xoshiro_next(s->rng) >> 11) * 0x1.0p-53;
    double r = sqrt(-2.0 * log(u1));
    double a = HB_TWO_PI * u2;
    s->spare_normal = r * sin(a);
    s->has_spare = 1;
    return r * cos(a);
}

void hb_normals(hb_state *s, double *out, int64_t n) {
    for (int64_t i = 0; i < n; i++) out[i] = normal(s);
}

/* ---- state ---- */

void hb_state_init(hb_state *s, const hb_params *p, double theta0, double omega0, uint64_t seed) {
    memset(s, 0, sizeof(*s));
    s->theta = theta0;
    s->omega = omega0;
    s->n_elements = p->n_elements;
    uint64_t x = seed;
    for (int i = 0; i < 4; i++) s->rng[i] = splitmix64(&x);
}

/* ---- forces ---- */

static inline double clip(double v, double lo, double hi) { return v < lo ? lo : (v > hi ? hi : v); }

/* Odd-symmetric piecewise-linear table on a grid x[0] = 0 < ... < x[n-1], held beyond the end. */
static double table_odd(double x, int n, const double *gx, const double *gf) {
    double ax = fabs(x);
    double f;
    if (ax >= gx[n - 1]) {
        f = gf[n - 1];
    } else {
        int lo = 0, hi = n - 1;
        while (hi - lo > 1) {
            int mid = (lo + hi) / 2;
            if (gx[mid] <= ax) lo = mid; else hi = mid;
        }
        double w = (ax - gx[lo]) / (gx[hi] - gx[lo]);
        f = gf[lo] + w * (gf[hi] - gf[lo]);
    }
    return x < 0.0 ? -f : f;
}

/* Lazy stop operator. The element deflections are held as e_i at the last commit plus one offset X
 * (s->ms_offset). While the motion since the commit is monotone, each element moves with the path until it
 * saturates: moving up by y >= 0, F(y) = F0 + sum_i k_i*min(y, up_i) with up_i = Delta_i - e_i the room of
 * each element free to move up (down likewise). The cache keeps F0, the total free slope and the MS_NEAR
 * smallest rooms in each direction, sorted, so F is exact and O(MS_NEAR) up to the next room beyond them
 * (the horizon). Only a reversal, or motion past the horizon, needs the O(N) commit
 * delta_i = clip(clip(e_i + X) + dx). */
#define MS_NEAR 8

typedef struct {
    double f0, slope_up, slope_down, room_up, room_down; /* room_*: horizon of the exact expansion */
    int n_up, n_down;
    int cur_up, cur_down; /* how many near rooms the last evaluation had passed (a search hint) */
    double r_up[MS_NEAR + 1], k_up[MS_NEAR + 1], r_down[MS_NEAR + 1], k_down[MS_NEAR + 1];
    /* prefix sums over the sorted near rooms: K[c] = sum_{j<c} k_j, R[c] = sum_{j<c} k_j*r_j */
    double K_up[MS_NEAR + 1], R_up[MS_NEAR + 1], K_down[MS_NEAR + 1], R_down[MS_NEAR + 1];
    /* the linear pieces a + b*y that the RK4 stages of the current sub-step almost always fall in:
     * y in [up_lo, up_hi] (moving on up from X >= 0) and [dn_lo, dn_hi] (on down from X <= 0) */
    double up_lo, up_hi, up_a, up_b, dn_lo, dn_hi, dn_a, dn_b;
    /* RK4 polynomial P(hA) of the linear stretch, for the last stiffness it was computed for */
    double aff_kappa, aff_gamma, aff_h, aff_P[4];
} ms_cache;

/* Keep the near+1 smallest rooms (sorted) with their stiffness. */
static inline void near_insert(double *r, double *k, int *n, int near, double room, double stiff) {
    int m = *n;
    if (m == near + 1 && room >= r[near]) return;
    int j = m < near + 1 ? m : near;
    while (j > 0 && r[j - 1] > room) {
        r[j] = r[j - 1];
        k[j] = k[j - 1];
        j--;
    }
    r[j] = room;
    k[j] = stiff;
    if (m < near + 1) *n = m + 1;
}

/* Fill the cache from the committed deflections e_i (no change to the state). */
static void ms_fill(const hb_params *p, const hb_state *s, ms_cache *c) {
    double f0[4] = {0.0, 0.0, 0.0, 0.0}, su[4] = {0.0, 0.0, 0.0, 0.0}, sd[4] = {0.0, 0.0, 0.0, 0.0};
    const double *q = s->deflection, *ks = p->ms_stiffness, *Ds = p->ms_delta;
    const int n = p->n_elements;
    const int near = MS_NEAR;
    c->n_up = c->n_down = 0;
    for (int i = 0; i < n; i++) {
        int j = i & 3;
        double k = ks[i], D = Ds[i], d = q[i];
        f0[j] += k * d;
        double up = D - d, down = D + d;
        if (up > 0.0) {
            su[j] += k;
            near_insert(c->r_up, c->k_up, &c->n_up, near, up, k);
        }
        if (down > 0.0) {
            sd[j] += k;
            near_insert(c->r_down, c->k_down, &c->n_down, near, down, k);
        }
    }
    c->f0 = (f0[0] + f0[1]) + (f0[2] + f0[3]);
    c->slope_up = (su[0] + su[1]) + (su[2] + su[3]);
    c->slope_down = (sd[0] + sd[1]) + (sd[2] + sd[3]);
    /* beyond the MS_NEAR nearest rooms the expansion needs the next one as its horizon */
    c->room_up = c->n_up > near ? c->r_up[near] : HUGE_VAL;
    c->room_down = c->n_down > near ? c->r_down[near] : HUGE_VAL;
    if (c->n_up > near) c->n_up = near;
    if (c->n_down > near) c->n_down = near;
    c->K_up[0] = c->R_up[0] = c->K_down[0] = c->R_down[0] = 0.0;
    for (int j = 0; j < c->n_up; j++) {
        c->K_up[j + 1] = c->K_up[j] + c->k_up[j];
        c->R_up[j + 1] = c->R_up[j] + c->k_up[j] * c->r_up[j];
    }
    for (int j = 0; j < c->n_down; j++) {
        c->K_down[j + 1] = c->K_down[j] + c->k_down[j];
        c->R_down[j + 1] = c->R_down[j] + c->k_down[j] * c->r_down[j];
    }
    c->cur_up = c->cur_down = 0;
    c->aff_h = -1.0; /* no P(hA) cached yet */
}

/* Is the path "X since the commit, then dx" monotone and within the horizon? */
static inline int ms_linear(ms_cache *c, double X, double dx) {
    double y = X + dx;
    return (dx >= 0.0 && X >= 0.0 && y <= c->room_up) || (dx <= 0.0 && X <= 0.0 && -y <= c->room_down);
}

/* Number of sorted rooms r[0..n) below y, searched from the hint c. */
static inline int ms_count(const double *r, int n, int c, double y) {
    while (c > 0 && r[c - 1] >= y) c--;
    while (c < n && r[c] < y) c++;
    return c;
}

/* Force after a monotone displacement y from the commit point, |y| within the horizon:
 * F = F0 + y*(slope - K[c]) + R[c] with c the rooms already passed. */
static inline double ms_expand_up(ms_cache *c, double y) {
    int n = c->cur_up = ms_count(c->r_up, c->n_up, c->cur_up, y);
    return c->f0 + y * (c->slope_up - c->K_up[n]) + c->R_up[n];
}

static inline double ms_expand_down(ms_cache *c, double y) {
    int n = c->cur_down = ms_count(c->r_down, c->n_down, c->cur_down, -y);
    return c->f0 + y * (c->slope_down - c->K_down[n]) - c->R_down[n];
}

static inline double ms_expand(ms_cache *c, double y) { return y >= 0.0 ? ms_expand_up(c, y) : ms_expand_down(c, y); }

/* The pieces of the expansion adjacent to the current offset X, for the stages of one sub-step. */
static inline void ms_segments(ms_cache *c, double X) {
    c->up_lo = HUGE_VAL;
    c->up_hi = -HUGE_VAL;
    c->dn_lo = HUGE_VAL;
    c->dn_hi = -HUGE_VAL;
    if (X >= 0.0) {
        int n = c->cur_up = ms_count(c->r_up, c->n_up, c->cur_up, X);
        c->up_lo = X;
        c->up_hi = n < c->n_up ? c->r_up[n] : c->room_up;
        c->up_a = c->f0 + c->R_up[n];
        c->up_b = c->slope_up - c->K_up[n];
    }
    if (X <= 0.0) {
        int n = c->cur_down = ms_count(c->r_down, c->n_down, c->cur_down, -X);
        c->dn_hi = X;
        c->dn_lo = -(n < c->n_down ? c->r_down[n] : c->room_down);
        c->dn_a = c->f0 - c->R_down[n];
        c->dn_b = c->slope_down - c->K_down[n];
    }
}

/* Advance every element by the sub-step's displacement dx (stop operator), lazily. */
static void ms_commit(const hb_params *p, hb_state *s, ms_cache *c, double dx) {
    double X = s->ms_offset;
    if (ms_linear(c, X, dx)) {
        s->ms_offset = X + dx;
        return;
    }
    double *q = s->deflection;
    for (int i = 0; i < p->n_elements; i++) {
        double D = p->ms_delta[i];
        q[i] = clip(clip(q[i] + X, -D, D) + dx, -D, D);
    }
    s->ms_offset = 0.0;
    ms_fill(p, s, c);
}

static inline __attribute__((always_inline)) double maxwell_force(const hb_params *p, const hb_state *s,
                                                                   ms_cache *c, double dx) {
    double X = s->ms_offset, y = X + dx;
    if (y >= c->up_lo && y <= c->up_hi) return c->up_a + c->up_b * y;
    if (y >= c->dn_lo && y <= c->dn_hi) return c->dn_a + c->dn_b * y;
    if (dx >= 0.0 && X >= 0.0 && y <= c->room_up) return ms_expand_up(c, y);
    if (dx <= 0.0 && X <= 0.0 && -y <= c->room_down) return ms_expand_down(c, y);
    double f = 0.0;
    const double *k = p->ms_stiffness, *d = p->ms_delta, *q = s->deflection;
    for (int i = 0; i < p->n_elements; i++) f += k[i] * clip(clip(q[i] + X, -d[i], d[i]) + dx, -d[i], d[i]);
    return f;
}

/* Maxwell-slip force at the current state (the lazy offset is always within its horizon). */
static inline double maxwell_now(ms_cache *c, double X) {
    return X >= 0.0 ? c->up_a + c->up_b * X : c->dn_a + c->dn_b * X;
}

void hb_deflections(const hb_params *p, const hb_state *s, double *out) {
    for (int i = 0; i < p->n_elements; i++) {
        double D = p->ms_delta[i];
        out[i] = clip(s->deflection[i] + s->ms_offset, -D, D);
    }
}

/* ---- state-variable friction models: LuGre, generalized Maxwell-slip, continuous hysteresis ----
 * Each is evaluated inside the RK4 stages like the Maxwell-slip elements: the state committed at the start of
 * the sub-step is advanced over the stage's displacement dx (monotone within a sub-step) and time offset t,
 * without being changed; the sub-step's displacement then commits it (docs/plant.md, "Friction models"). */

/* Stribeck curve Fc + (Fs - Fc)*exp(-|v/vs|^delta), N*m. */
static inline double stribeck_curve(double fc, double fs, double vs, double delta, double v) {
    if (vs <= 0.0 || fs == fc) return fc;
    double r = fabs(v / vs);
    double e = delta == 2.0 ? r * r : (delta == 1.0 ? r : pow(r, delta)); /* pow() costs ~10x a product */
    return fc + (fs - fc) * exp(-e);
}

/* LuGre bristle deflection after the displacement dx from z0 at a constant g: dz/dx = 1 - s0*sgn(dx)*z/g is
 * integrated exactly, z = zs + (z0 - zs)*exp(-s0*|dx|/g) with zs = sgn(dx)*g/s0. */
static inline double lugre_z(const hb_params *p, double z0, double dx, double g) {
    if (dx == 0.0) return z0;
    double zs = (dx > 0.0 ? g : -g) / p->lg_sigma0;
    return zs + (z0 - zs) * exp(-(p->lg_sigma0 * fabs(dx) / g));
}

static inline double lugre_force(const hb_params *p, double z0, double dx, double omega) {
    double g = stribeck_curve(p->lg_coulomb, p->lg_static, p->lg_stribeck_velocity, p->lg_exponent, omega);
    double z = lugre_z(p, z0, dx, g);
    double zdot = omega - p->lg_sigma0 * fabs(omega) * z / g;
    return p->lg_sigma0 * z + p->lg_sigma1 * zdot + p->lg_sigma2 * omega;
}

/* One GMS element from force f0 and slip state slip0, after the displacement dx over the time t at velocity
 * omega. Sticking: f0 + k*dx, until it reaches +-alpha*s; slipping on in the same direction: the exact
 * solution of dF/dt = C*(dir - F/(alpha*s)) at constant s, F = target + (f0 - target)*exp(-C*t/(alpha*s)). */
static inline double gms_element(const hb_params *p, int i, double f0, int slip0, double dx, double t,
                                 double s_omega, int *slip_out) {
    *slip_out = slip0;
    if (dx == 0.0) return f0;
    int dir = dx > 0.0 ? 1 : -1;
    double cap = p->gms_alpha[i] * s_omega;
    if (slip0 == dir) {
        double target = dir > 0 ? cap : -cap;
        if (isinf(p->gms_attraction)) return target;
        return target + (f0 - target) * exp(-(p->gms_attraction * t / cap));
    }
    double f = f0 + p->gms_k[i] * dx;
    *slip_out = 0;
    if (f >= cap) {
        f = cap;
        *slip_out = 1;
    } else if (f <= -cap) {
        f = -cap;
        *slip_out = -1;
    }
    return f;
}

static inline double gms_force(const hb_params *p, const hb_state *s, double dx, double t, double omega) {
    double sv = stribeck_curve(p->gms_coulomb, p->gms_static, p->gms_stribeck_velocity, p->gms_exponent, omega);
    double f = 0.0;
    int slip;
    for (int i = 0; i < p->gms_n; i++) f += gms_element(p, i, s->gms_f[i], s->gms_slip[i], dx, t, sv, &slip);
    return f + p->gms_sigma2 * omega;
}

static void gms_commit(const hb_params *p, hb_state *s, double dx, double t, double omega) {
    double sv = stribeck_curve(p->gms_coulomb, p->gms_static, p->gms_stribeck_velocity, p->gms_exponent, omega);
    for (int i = 0; i < p->gms_n; i++) {
        int slip;
        s->gms_f[i] = gms_element(p, i, s->gms_f[i], s->gms_slip[i], dx, t, sv, &slip);
        s->gms_slip[i] = slip;
    }
}

/* Virgin curve phi(x) = h*(1 - (d/(d+|x|))^2)*sgn(x), N*m. */
static inline double hy_phi(const hb_params *p, double x) {
    double r = p->hy_d / (p->hy_d + fabs(x));
    double f = p->hy_h * (1.0 - r * r);
    return x < 0.0 ? -f : f;
}

/* The reversal stack as a walk sees it: the committed points, plus one pending reversal point on top. */
typedef struct {
    const double *xs, *fs;
    int m;          /* points in use, the pending one included */
    int pending;    /* index of the pending point, or -1 */
    double px, pf;  /* the pending point */
} hy_view;

static inline double hy_x_at(const hy_view *w, int j) { return j == w->pending ? w->px : w->xs[j]; }
static inline double hy_f_at(const hy_view *w, int j) { return j == w->pending ? w->pf : w->fs[j]; }

/* Force on the branch that starts at the top reversal point (the virgin curve on an empty stack): Masing,
 * F = F_r + 2*phi((x - x_r)/2). */
static inline double hy_branch(const hb_params *p, const hy_view *w, double x) {
    if (w->m == 0) return hy_phi(p, x);
    return hy_f_at(w, w->m - 1) + 2.0 * hy_phi(p, 0.5 * (x - hy_x_at(w, w->m - 1)));
}

/* Walk the stack over the monotone displacement dx from the committed position: a reversal pushes the start
 * point (when the stack is full, the newest and smallest loop is closed instead: the last reversal point is
 * forgotten and the force rejoins the enclosing branch), and every loop the path closes is wiped out
 * (the top pair is popped when the path reaches the second point from the top; a single point x_1 when it
 * reaches -x_1, where the branch meets the virgin curve). Returns the view after the walk. */
static inline hy_view hy_walk(const hb_params *p, const hb_state *s, double dx, int *dropped) {
    hy_view w = {s->hy_xs, s->hy_fs, s->hy_m, -1, 0.0, 0.0};
    *dropped = 0;
    if (dx == 0.0) return w;
    int dir = dx > 0.0 ? 1 : -1;
    double x = s->hy_x;
    if (s->hy_dir != 0 && dir != s->hy_dir) {
        double f = hy_branch(p, &w, x);
        if (w.m == p->hy_stack) {
            w.m -= 2;
            *dropped = 1;
        }
        w.pf = f;
        w.px = x;
        w.pending = w.m;
        w.m += 1;
    }
    double xe = x + dx;
    while (w.m > 0) {
        double wipe = w.m == 1 ? -hy_x_at(&w, 0) : hy_x_at(&w, w.m - 2);
        if ((xe - wipe) * dir < 0.0) break;
        w.m -= w.m == 1 ? 1 : 2;
    }
    return w;
}

static inline double hy_force(const hb_params *p, const hb_state *s, double dx) {
    int dropped;
    hy_view w = hy_walk(p, s, dx, &dropped);
    return hy_branch(p, &w, s->hy_x + dx);
}

static void hy_commit(const hb_params *p, hb_state *s, double dx) {
    if (dx == 0.0) return;
    int dropped;
    hy_view w = hy_walk(p, s, dx, &dropped);
    if (w.pending >= 0 && w.pending < w.m) {
        s->hy_xs[w.pending] = w.px;
        s->hy_fs[w.pending] = w.pf;
    }
    s->hy_m = w.m;
    s->hy_dropped += dropped;
    if (w.pending >= 0 && w.pending + 1 > s->hy_depth_max) s->hy_depth_max = w.pending + 1;
    s->hy_x += dx;
    s->hy_dir = dx > 0.0 ? 1 : -1;
}

/* Force of every state-variable model after the displacement dx and time t from the committed state, at
 * velocity omega, N*m. */
static inline double model_force(const hb_params *p, const hb_state *s, double dx, double t, double omega) {
    double f = 0.0;
    if (p->lugre) f += lugre_force(p, s->lg_z, dx, omega);
    if (p->gms_n > 0) f += gms_force(p, s, dx, t, omega);
    if (p->hy_stack > 0) f += hy_force(p, s, dx);
    return f;
}

/* Commit the displacement dx over the time t, ending at velocity omega. */
static void model_commit(const hb_params *p, hb_state *s, double dx, double t, double omega) {
    if (p->lugre) {
        double g = stribeck_curve(p->lg_coulomb, p->lg_static, p->lg_stribeck_velocity, p->lg_exponent, omega);
        s->lg_z = lugre_z(p, s->lg_z, dx, g);
    }
    if (p->gms_n > 0) gms_commit(p, s, dx, t, omega);
    if (p->hy_stack > 0) hy_commit(p, s, dx);
}

/* What a run's parameters switch on, decided once per hb_run call instead of in every RK4 stage. */
typedef struct {
    int extras;        /* cogging or tables present */
    int models;        /* LuGre, GMS or the continuous hysteresis present */
    int dry;           /* Coulomb or Stribeck present */
    int asym_viscous;  /* viscous differs by direction */
    int spring;        /* a linear spring is present */
    double k_spring, b_pos, b_neg; /* copies, so the RK4 stages keep them in registers */
    int affine;        /* linear mechanics between saturations: the closed-form RK4 step applies */
} hb_features;

static hb_features features_of(const hb_params *p) {
    hb_features f;
    f.extras = p->n_cogging > 0 || p->n_restoring > 0 || p->n_damping > 0;
    f.dry = p->coulomb_pos > 0.0 || p->coulomb_neg > 0.0 || p->stribeck_excess > 0.0;
    f.asym_viscous = p->viscous_pos != p->viscous_neg;
    f.spring = p->spring != 0.0;
    f.k_spring = p->spring;
    f.b_pos = p->viscous_pos;
    f.b_neg = p->viscous_neg;
    f.models = p->lugre || p->gms_n > 0 || p->hy_stack > 0;
    f.affine = !f.extras && !f.dry && !f.asym_viscous && !f.models;
    return f;
}

/* Every smooth (single-valued) force resisting motion, at angle theta and velocity omega. */
static inline __attribute__((always_inline)) double smooth_force(const hb_params *p, const hb_state *s,
                                                                  ms_cache *c, const hb_features ft,
                                                                  double theta, double omega, double t) {
    double f = maxwell_force(p, s, c, theta - s->theta);
    if (ft.models) f += model_force(p, s, theta - s->theta, t, omega);
    if (ft.spring) f += ft.k_spring * theta;
    f += (ft.asym_viscous && omega < 0.0 ? ft.b_neg : ft.b_pos) * omega;
    if (ft.extras) {
        for (int j = 0; j < p->n_cogging; j++)
            f += p->cogging_amplitude[j] * sin(p->cogging_order[j] * theta + p->cogging_phase[j]);
        if (p->n_restoring > 0) f += table_odd(theta, p->n_restoring, p->restoring_x, p->restoring_f);
        if (p->n_damping > 0) f += table_odd(omega, p->n_damping, p->damping_v, p->damping_f);
    }
    return f;
}

/* Total friction torque at the current state (excludes spring and cogging), N*m. */
static double friction_now(const hb_params *p, const hb_state *s, ms_cache *c) {
    double f = maxwell_now(c, s->ms_offset);
    f += (s->omega >= 0.0 ? p->viscous_pos : p->viscous_neg) * s->omega;
    f += s->coulomb_force;
    if (p->n_restoring > 0) f += table_odd(s->theta, p->n_restoring, p->restoring_x, p->restoring_f);
    if (p->n_damping > 0) f += table_odd(s->omega, p->n_damping, p->damping_v, p->damping_f);
    f += model_force(p, s, 0.0, 0.0, s->omega);
    return f;
}

/* Coulomb/Stribeck level for motion in direction dir (+1/-1) at velocity omega, N*m (>= 0). */
static inline __attribute__((always_inline)) double coulomb_level(const hb_params *p, double dir, double omega) {
    double level = dir > 0.0 ? p->coulomb_pos : p->coulomb_neg;
    if (p->stribeck_velocity > 0.0) {
        double r = omega / p->stribeck_velocity;
        level += p->stribeck_excess * exp(-(r * r));
    }
    return level;
}

/* Classical RK4 over h; dir != 0 adds the sliding Coulomb/Stribeck force dir*level(omega). */
static inline __attribute__((always_inline)) void rk4(const hb_params *p, const hb_state *s, ms_cache *c,
                                                      const hb_features ft, double tau, double h, double dir,
                                                      double *th_out, double *om_out) {
    const double inv_j = 1.0 / p->inertia;
    double th = s->theta, om = s->omega;
    double k1x = om;
    double f1 = smooth_force(p, s, c, ft, th, om, 0.0);
    if (dir != 0.0) f1 += dir * coulomb_level(p, dir, om);
    double k1v = (tau - f1) * inv_j;
    double k2x = om + 0.5 * h * k1v;
    double f2 = smooth_force(p, s, c, ft, th + 0.5 * h * k1x, k2x, 0.5 * h);
    if (dir != 0.0) f2 += dir * coulomb_level(p, dir, k2x);
    double k2v = (tau - f2) * inv_j;
    double k3x = om + 0.5 * h * k2v;
    double f3 = smooth_force(p, s, c, ft, th + 0.5 * h * k2x, k3x, 0.5 * h);
    if (dir != 0.0) f3 += dir * coulomb_level(p, dir, k3x);
    double k3v = (tau - f3) * inv_j;
    double k4x = om + h * k3v;
    double f4 = smooth_force(p, s, c, ft, th + h * k3x, k4x, h);
    if (dir != 0.0) f4 += dir * coulomb_level(p, dir, k4x);
    double k4v = (tau - f4) * inv_j;
    *th_out = th + h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
    *om_out = om + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
}

/* Classical RK4 on a linear stretch, in closed form. With no Coulomb, cogging or tables, a symmetric viscous c
 * and every stage inside one linear piece F = a + b*y of the Maxwell-slip force, the mechanics are linear:
 * e' = w, w' = g - kappa*e - gamma*w for the displacement e from theta_n, with kappa = (b + k)/J,
 * gamma = c/J, g = (tau - a - b*X - k*theta_n)/J. One RK4 step is then exactly
 * [e, w]_1 = [0, w_0] + h*P(hA)*(A*[0, w_0] + [0, g]), P(Z) = I + Z/2 + Z^2/6 + Z^3/24, which is a short
 * dependency chain instead of four dependent stages. The stage displacements are still computed, only to
 * check that every stage stayed in the piece; otherwise (0 returned) the caller runs the general RK4. */
static inline __attribute__((always_inline)) int affine_step(const hb_params *p, hb_state *s, ms_cache *c,
                                                            const hb_features ft, double tau, double h) {
    const double th = s->theta, om = s->omega, X = s->ms_offset;
    const int up = om > 0.0 || (om == 0.0 && X >= 0.0);
    double lo, hi, a, b;
    if (up) {
        lo = c->up_lo; hi = c->up_hi; a = c->up_a; b = c->up_b;
    } else {
        lo = c->dn_lo; hi = c->dn_hi; a = c->dn_a; b = c->dn_b;
    }
    if (!(lo <= hi)) return 0;
    const double inv_j = 1.0 / p->inertia;
    const double kappa = (b + ft.k_spring) * inv_j, gamma = ft.b_pos * inv_j;
    if (kappa != c->aff_kappa || gamma != c->aff_gamma || h != c->aff_h) {
        /* Z = hA with A = [[0, 1], [-kappa, -gamma]]; P = I + Z/2 + Z^2/6 + Z^3/24 */
        double z00 = 0.0, z01 = h, z10 = -h * kappa, z11 = -h * gamma;
        double q00 = z00 * z00 + z01 * z10, q01 = z00 * z01 + z01 * z11;
        double q10 = z10 * z00 + z11 * z10, q11 = z10 * z01 + z11 * z11;
        double r00 = q00 * z00 + q01 * z10, r01 = q00 * z01 + q01 * z11;
        double r10 = q10 * z00 + q11 * z10, r11 = q10 * z01 + q11 * z11;
        c->aff_P[0] = 1.0 + z00 / 2.0 + q00 / 6.0 + r00 / 24.0;
        c->aff_P[1] = z01 / 2.0 + q01 / 6.0 + r01 / 24.0;
        c->aff_P[2] = z10 / 2.0 + q10 / 6.0 + r10 / 24.0;
        c->aff_P[3] = 1.0 + z11 / 2.0 + q11 / 6.0 + r11 / 24.0;
        c->aff_kappa = kappa;
        c->aff_gamma = gamma;
        c->aff_h = h;
    }
    const double g = (tau - a - b * X - ft.k_spring * th) * inv_j;
    const double u0 = om, u1 = g - gamma * om;
    const double e_new = h * (c->aff_P[0] * u0 + c->aff_P[1] * u1);
    const double om_new = om + h * (c->aff_P[2] * u0 + c->aff_P[3] * u1);
    /* stage displacements of the same RK4 step, for the check only */
    const double e2 = 0.5 * h * om, k2x = om + 0.5 * h * u1;
    const double e3 = 0.5 * h * k2x, k3x = om + 0.5 * h * (g - kappa * e2 - gamma * k2x);
    const double e4 = h * k3x;
    const double l = lo - X, r = hi - X;
    if (!(e2 >= l && e2 <= r && e3 >= l && e3 <= r && e4 >= l && e4 <= r && e_new >= l && e_new <= r))
        return 0;
    s->theta = th + e_new;
    s->omega = om_new;
    s->coulomb_force = 0.0;
    ms_commit(p, s, c, e_new);
    return 1;
}

/* One sub-step of length h under constant motor torque tau.
 * Smooth forces: classical RK4. Coulomb/Stribeck while sliding in a known direction: inside the same RK4
 * step. If the rotor is at rest or would reverse within the step: RK4 without Coulomb, then an implicit
 * (Moreau) velocity projection, so sticking is exact and there is no chattering. Finally the element
 * deflections are committed with the step's displacement (stop operator). */
static inline __attribute__((always_inline)) void substep(const hb_params *p, hb_state *s, ms_cache *c,
                                                          const hb_features ft, double tau,
                    double h) {
    const double J = p->inertia;
    double th = s->theta, om = s->omega;
    double th_new, om_new;
    if (ft.affine && affine_step(p, s, c, ft, tau, h)) {
        ms_segments(c, s->ms_offset);
        return;
    }

    if (!ft.dry) {
        rk4(p, s, c, ft, tau, h, 0.0, &th_new, &om_new);
        s->coulomb_force = 0.0;
    } else {
        double dir = om > 0.0 ? 1.0 : (om < 0.0 ? -1.0 : 0.0);
        int sliding = 0;
        if (dir != 0.0) {
            rk4(p, s, c, ft, tau, h, dir, &th_new, &om_new);
            sliding = om_new * dir > 0.0;
            if (sliding) s->coulomb_force = dir * coulomb_level(p, dir, om_new);
        }
        if (!sliding && dir != 0.0) {
            /* The velocity reaches zero inside the step. Locate that instant (linear in the sliding step's
             * velocity), slide up to it with the friction of the old direction, stop there, and let the rest
             * of the step decide between sticking and sliding the other way. Projecting the whole step at
             * once would apply the new direction's friction from the start of the step: the reversal instant
             * is then quantised to the step grid, and a mass sliding under a sine keeps whatever mean-velocity
             * offset its start gave it (measured: a creep of up to 3.5e-3*G/(m*omega^2) per period). */
            double t1 = h * om / (om - om_new);
            if (t1 > 0.0 && t1 < h) {
                double th1, om1;
                rk4(p, s, c, ft, tau, t1, dir, &th1, &om1);
                s->theta = th1;
                s->omega = 0.0;
                s->coulomb_force = dir * coulomb_level(p, dir, 0.0);
                ms_commit(p, s, c, th1 - th);
                ms_segments(c, s->ms_offset);
                if (ft.models) model_commit(p, s, th1 - th, t1, 0.0);
                h -= t1;
                th = th1;
                om = 0.0;
            }
        }
        if (!sliding) {
            rk4(p, s, c, ft, tau, h, 0.0, &th_new, &om_new);
            double free_dir = om_new >= 0.0 ? 1.0 : -1.0;
            double dv = h * coulomb_level(p, free_dir, om) / J;
            double om_free = om_new;
            if (fabs(om_free) <= dv) {
                om_new = 0.0;
            } else {
                om_new = om_free - free_dir * dv;
            }
            /* the velocity lost to friction accrued uniformly over the sub-step */
            th_new -= 0.5 * h * (om_free - om_new);
            s->coulomb_force = J * (om_free - om_new) / h;
        }
    }

    s->theta = th_new;
    s->omega = om_new;
    ms_commit(p, s, c, th_new - th);
    ms_segments(c, s->ms_offset);
    if (ft.models) model_commit(p, s, th_new - th, h, om_new);
}

/* the Maxwell-slip cache fits the caller's storage (C99: a negative array size if not) */
typedef char hb_run_cache_fits[sizeof(ms_cache) <= sizeof(((hb_run_cache *)0)->words) ? 1 : -1];

static int run_samples(const hb_params *p, hb_state *s, ms_cache *c, const double *u, int64_t n, double dt,
                       int substeps, int mode, hb_position_loop *loop, hb_outputs *out);

int hb_run(const hb_params *p, hb_state *s, const double *u, int64_t n, double dt, int substeps,
           int mode, hb_outputs *out) {
    ms_cache cache;
    ms_fill(p, s, &cache);
    if (mode == HB_MODE_POSITION) return -2;  /* it needs its loop: hb_run_position */
    return run_samples(p, s, &cache, u, n, dt, substeps, mode, NULL, out);
}

int hb_run_position(const hb_params *p, hb_state *s, hb_position_loop *loop, const double *target,
                    int64_t n, double dt, int substeps, hb_outputs *out) {
    ms_cache cache;
    ms_fill(p, s, &cache);
    return run_samples(p, s, &cache, target, n, dt, substeps, HB_MODE_POSITION, loop, out);
}

int hb_run_cached(const hb_params *p, hb_state *s, hb_run_cache *cache, const double *u, int64_t n, double dt,
                  int substeps, int mode, hb_outputs *out) {
    ms_cache *c = (ms_cache *)(void *)cache->words;
    if (!cache->valid) {
        ms_fill(p, s, c);
        cache->valid = 1;
    }
    if (mode == HB_MODE_POSITION) return -2;  /* it needs its loop: hb_run_position */
    int rc = run_samples(p, s, c, u, n, dt, substeps, mode, NULL, out);
    if (rc != 0) cache->valid = 0;  /* a non-finite state: whatever comes next starts from a fresh cache */
    return rc;
}

/* hb_run from a filled Maxwell-slip cache `c` of the state `s` (kept up to date as the state advances). */
static int run_samples(const hb_params *p, hb_state *s, ms_cache *c, const double *u, int64_t n, double dt,
                       int substeps, int mode, hb_position_loop *loop, hb_outputs *out) {
    const double h = dt / substeps;
    const double kt_true = p->torque_constant * (1.0 + p->torque_constant_error);
    const double lag_a = p->current_lag > 0.0 ? exp(-dt / p->current_lag) : 0.0;
    const double lag_avg = p->current_lag > 0.0 ? p->current_lag / dt * (1.0 - lag_a) : 0.0;
    const hb_features ft = features_of(p);
    ms_segments(c, s->ms_offset);

    for (int64_t k = 0; k < n; k++) {
        /* 1. measure at t_k */
        double i_meas = s->current;
        if (p->noise_current > 0.0) i_meas += p->noise_current * normal(s);
        double th_noisy = s->theta;
        if (p->noise_position > 0.0) th_noisy += p->noise_position * normal(s);
        double pos;
        int64_t counts = 0;
        if (p->counts_per_rev > 0) {
            double cpr = (double)p->counts_per_rev;
            counts = (int64_t)floor(th_noisy * cpr / HB_TWO_PI + 0.5);
            pos = (double)counts * HB_TWO_PI / cpr;
        } else {
            pos = th_noisy;
        }
        double friction = friction_now(p, s, c);

        /* 2. command */
        double i_cmd;
        if (mode == HB_MODE_VELOCITY) {
            double v_est = s->has_prev ? (pos - s->prev_position) / dt : 0.0;
            double err = u[k] - v_est;
            double integral = s->pi_integral + err * dt;
            i_cmd = p->velocity_kp * err + p->velocity_ki * integral;
            if (i_cmd > p->current_limit) {
                i_cmd = p->current_limit;
                if (err < 0.0) s->pi_integral = integral; /* integrate only out of saturation */
            } else if (i_cmd < -p->current_limit) {
                i_cmd = -p->current_limit;
                if (err > 0.0) s->pi_integral = integral;
            } else {
                s->pi_integral = integral;
            }
        } else if (mode == HB_MODE_POSITION) {
            double v_est = s->has_prev ? (pos - s->prev_position) / dt : 0.0;
            if (!loop->est_valid || loop->est_time != s->time) {  /* (re)start from the measurement */
                loop->est_position = pos;
                loop->est_velocity = v_est;
                loop->integral = 0.0;
                loop->est_valid = 1;
            } else if (loop->pll_hz > 0.0) {
                const double w = HB_TWO_PI * loop->pll_hz;
                loop->est_position += dt * loop->est_velocity;
                const double e = pos - loop->est_position;
                loop->est_position += 2.0 * w * dt * e;
                loop->est_velocity += w * w * dt * e;
            }
            loop->est_time = s->time + dt;  /* where the loop's state stands after this sample's step */
            if (loop->pll_hz > 0.0) v_est = loop->est_velocity;
            double tau_cmd = loop->feedforward + loop->kd * (loop->velocity - v_est);
            if (!isnan(u[k])) {
                const double e = u[k] - pos;
                loop->integral = clip(loop->integral + loop->ki * e * dt, -loop->ilimit, loop->ilimit);
                tau_cmd += loop->kp * e + loop->integral;
            } else {
                tau_cmd += loop->integral;
            }
            tau_cmd = clip(tau_cmd, -loop->torque_limit, loop->torque_limit);
            i_cmd = clip(tau_cmd / p->torque_constant, -p->current_limit, p->current_limit);
        } else {
            i_cmd = clip(u[k], -p->current_limit, p->current_limit);
        }
        s->prev_position = pos;
        s->has_prev = 1;

        /* 3. delay, current-loop lag, torque constant, offset, drift */
        double i_del = i_cmd;
        if (p->delay_samples > 0) {
            i_del = s->delay_buf[s->delay_pos];
            s->delay_buf[s->delay_pos] = i_cmd;
            s->delay_pos = (s->delay_pos + 1) % p->delay_samples;
        }
        double i_avg;
        if (p->current_lag > 0.0) {
            i_avg = i_del + (s->current - i_del) * lag_avg;
            s->current = i_del + (s->current - i_del) * lag_a;
        } else {
            i_avg = i_del;
            s->current = i_del;
        }
        double tau = kt_true * i_avg + p->torque_offset + p->torque_drift * s->time;

        out->theta[k] = s->theta;
        out->omega[k] = s->omega;
        out->friction[k] = friction;
        out->current_cmd[k] = i_cmd;
        out->current_meas[k] = i_meas;
        out->torque[k] = tau;
        out->position_meas[k] = pos;
        out->counts[k] = counts;

        /* 4. mechanics over [t_k, t_k+1) */
        for (int j = 0; j < substeps; j++) substep(p, s, c, ft, tau, h);
        s->time += dt;
        if (!isfinite(s->theta) || !isfinite(s->omega)) return -1;
    }
    return 0;
}

void hb_friction_path(const hb_params *p, hb_state *s, const double *x, const double *v, int64_t n, double dt,
                      double *out) {
    ms_cache cache;
    ms_fill(p, s, &cache);
    ms_segments(&cache, s->ms_offset);
    for (int64_t k = 0; k < n; k++) {
        if (k > 0) {
            double dx = x[k] - x[k - 1];
            ms_commit(p, s, &cache, dx);
            ms_segments(&cache, s->ms_offset);
            model_commit(p, s, dx, dt, v[k]);
            s->time += dt;
        }
        s->theta = x[k];
        s->omega = v[k];
        double dir = v[k] > 0.0 ? 1.0 : (v[k] < 0.0 ? -1.0 : 0.0);
        s->coulomb_force = dir == 0.0 ? 0.0 : dir * coulomb_level(p, dir, v[k]);
        out[k] = friction_now(p, s, &cache);
    }
}

void hb_stop_operator(const double *x, int64_t n, const double *deltas, int m, double *state,
                      double *out) {
    if (n <= 0) return;
    for (int j = 0; j < m; j++) out[j] = state[j];
    for (int64_t i = 1; i < n; i++) {
        double dx = x[i] - x[i - 1];
        double *row = out + i * (int64_t)m;
        const double *prev = row - m;
        for (int j = 0; j < m; j++) row[j] = clip(prev[j] + dx, -deltas[j], deltas[j]);
    }
    for (int j = 0; j < m; j++) state[j] = out[(n - 1) * (int64_t)m + j];
}
