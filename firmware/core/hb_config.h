/* Compile-time sizes and the floating-point policy of the firmware core. A target overrides them with
 * -D flags (see firmware/Makefile); every buffer of the core is sized here, nothing is allocated.
 *
 * Floating-point policy (docs/firmware.md):
 *  - hb_real is the type of every control-path computation: limit checks, velocity estimate, PI loop.
 *    It is double by default. A target whose FPU is single precision only (Cortex-M4F) may build with
 *    -DHB_REAL_FLOAT; then the PI loop and limit checks run in float, and bit-identity with the host's
 *    double-precision reference holds only in current mode (the setpoint is a float32 on the wire).
 *  - Time is never a float: the core counts microseconds in uint64_t and samples in uint64_t.
 *  - Wire values are float32 (setpoints, currents) or float64 (CONFIG, stored as received).
 */
#ifndef HB_CONFIG_H
#define HB_CONFIG_H

#ifndef HB_BUFFER_CAPACITY
#define HB_BUFFER_CAPACITY 8192    /* setpoint ring buffer, samples (float32 each) */
#endif
#ifndef HB_MAX_BLOCK
#define HB_MAX_BLOCK 512           /* largest setpoint block accepted and sample block sent, samples */
#endif
#define HB_MAX_WINDOW 20           /* over-speed window W = rate/1000 at 20 kHz, samples */

#ifdef HB_REAL_FLOAT
typedef float hb_real;
#else
typedef double hb_real;
#endif

#endif
