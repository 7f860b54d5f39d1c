/* Nucleo-F446RE wiring and scaling (docs/firmware-nucleo-f446re.md). Change these for your amplifier. */
#ifndef BOARD_H
#define BOARD_H

#define BOARD_MODEL "HB-NUCLEO-F446RE"
#define BOARD_SERIAL "F446-0001"
#define BOARD_BAUD 2000000u           /* USART2 = ST-LINK virtual COM port */

/* Current set value: DAC1 OUT1 (PA4, 0..3.3 V, 12 bit) through the bipolar level shifter of the document:
 * V_amp = (V_dac - 1.65 V) * 10/1.65, so mid-scale (code 2048) is 0 A and full scale is +-AMPS_FULL_SCALE. */
#define BOARD_DAC_AMPS_FULL_SCALE 10.0f  /* A at +10 V on the amplifier's set-value input */
/* Current monitor: ADC1 IN6 (PA6) from the amplifier's monitor output through the same kind of divider:
 * code 2048 = 0 A, 0 and 4095 = -/+ ADC_AMPS_FULL_SCALE. */
#define BOARD_ADC_AMPS_FULL_SCALE 10.0f
/* Amplifier enable: PA8 (D7), active high. Encoder A/B: PA0/PA1 (TIM2, 32-bit, x4 quadrature). */

/* Velocity PI loop of the core, A/(rad/s) and A/rad: tune for your motor before closing the loop. */
#define BOARD_VELOCITY_KP 0.05
#define BOARD_VELOCITY_KI 1.0

#endif
