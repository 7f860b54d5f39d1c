/* Processor-in-the-loop target: the firmware core and the C plant on QEMU's mps2-an386 (Cortex-M4F,
 * 25 MHz), protocol v1 on the CMSDK APB UART0. Time comes from TIMER0, free-running at 25 MHz.
 * The UART holds one received byte, so its RX interrupt moves bytes into a ring that the main loop hands
 * to the core between ticks (a tick may compute hundreds of samples).
 * Pacing is chosen at build time (HB_TARGET_PACING): lockstep for bit-exact tests, realtime for the rate
 * benchmark. The plant's parameters come from the simulator configuration (sim_params.h, generated). */
#include <stdint.h>

#include "hb_device.h"
#include "hb_hal.h"
#include "hb_plant_hal.h"
#include "sim_params.h"

#ifndef HB_TARGET_PACING
#define HB_TARGET_PACING HB_LOCKSTEP
#endif
#ifndef HB_TARGET_MAX_BLOCK
#define HB_TARGET_MAX_BLOCK 128
#endif
#define SYSCLK_HZ 25000000u
#define TICK_US 1000u                /* realtime loop period */

#define UART0_DATA (*(volatile uint32_t *)0x40004000u)
#define UART0_STATE (*(volatile uint32_t *)0x40004004u)
#define UART0_CTRL (*(volatile uint32_t *)0x40004008u)
#define UART0_INTSTATUS (*(volatile uint32_t *)0x4000400Cu)
#define UART0_BAUDDIV (*(volatile uint32_t *)0x40004010u)
#define NVIC_ISER0 (*(volatile uint32_t *)0xE000E100u)
#define RX_RING 16384u                /* bytes, a power of two */
#define UART_TX_FULL 0x1u
#define UART_RX_FULL 0x2u
#define TIMER0_CTRL (*(volatile uint32_t *)0x40000000u)
#define TIMER0_VALUE (*(volatile uint32_t *)0x40000004u)
#define TIMER0_RELOAD (*(volatile uint32_t *)0x40000008u)

typedef struct {
    hb_plant_hal sim;  /* first: the core's hal pointer is the plant HAL's */
} an386_hal;

static an386_hal hal;
static hb_device device;

static volatile uint8_t rx_ring[RX_RING];
static volatile uint32_t rx_head, rx_tail;  /* written by the ISR / by the main loop */
static uint32_t rx_overruns;

/* The RX interrupt is cleared first, then the data register drained. Cleared last, it would also clear
 * the interrupt of a byte that arrived after the drain loop's final check: that byte then sits in the
 * one-byte RX register with no interrupt pending, QEMU takes no further byte, and the link is dead (the
 * cause of the unanswered GET_IDENTITY and HEARTBEAT seen in a fifth of fresh starts). */
void UART0_RX_Handler(void) {
    UART0_INTSTATUS = 0x2u;
    while (UART0_STATE & UART_RX_FULL) {
        uint8_t b = (uint8_t)UART0_DATA;
        if (rx_head - rx_tail < RX_RING) {
            rx_ring[rx_head % RX_RING] = b;
            rx_head++;
        } else {
            rx_overruns++;  /* the frame is lost; its CRC fails and the core counts it */
        }
    }
}

/* Time is read from CMSDK APB TIMER0, a free-running 32-bit down-counter at SYSCLK (wraps every 171 s),
 * extended to 64 bits here. Counting SysTick interrupts instead loses time whenever QEMU delivers two
 * expiries before the guest ran: the guest clock then ran slow and a realtime stream took up to twice its
 * nominal time. Only the main loop reads the clock. */
static uint64_t clock_ticks;
static uint32_t clock_last = 0xFFFFFFFFu;

static uint64_t now_us(void) {
    uint32_t value = TIMER0_VALUE;
    clock_ticks += (uint32_t)(clock_last - value);
    clock_last = value;
    return clock_ticks / (SYSCLK_HZ / 1000000u);
}

void hb_hal_serial_write(void *h, const uint8_t *data, size_t n) {
    (void)h;
    for (size_t i = 0; i < n; i++) {
        while (UART0_STATE & UART_TX_FULL) {
        }
        UART0_DATA = data[i];
    }
}

/* This board has no CAN controller; the core is set up for its serial link and never calls this. */
void hb_hal_can_write(void *h, uint16_t id, const uint8_t *data, uint8_t len) {
    (void)h;
    (void)id;
    (void)data;
    (void)len;
}

int main(void) {
    hal.sim.base = SIM_PLANT;
    for (int i = 0; i < 5; i++) hal.sim.substeps_by_rate[i] = SIM_SUBSTEPS[i];
    hal.sim.seed = SIM_SEED;
    hb_device_setup setup = {SIM_MODEL, SIM_SERIAL, "hilbench-sim c-core " HB_CORE_VERSION " mps2-an386",
                             SIM_CAPACITY, HB_TARGET_MAX_BLOCK, HB_TARGET_PACING, HB_LINK_SERIAL, 1,
                             SIM_VELOCITY_KP, SIM_VELOCITY_KI, 0};  /* no temperature sensor */
    hb_device_init(&device, &setup, &hal);
    UART0_BAUDDIV = 16;
    UART0_CTRL = 0xBu;  /* TX and RX enabled, RX interrupt */
    NVIC_ISER0 = 1u;
    TIMER0_RELOAD = 0xFFFFFFFFu;
    TIMER0_VALUE = 0xFFFFFFFFu;
    TIMER0_CTRL = 0x1u;  /* enabled, no interrupt */
    uint64_t next_tick = now_us();
    uint8_t rx[256];
    for (;;) {
        size_t n = 0;
        while (n < sizeof rx && rx_tail != rx_head) {
            rx[n++] = rx_ring[rx_tail % RX_RING];
            rx_tail++;
        }
        if (n) hb_device_rx_bytes(&device, rx, n, now_us());
        uint64_t t = now_us();
        if (HB_TARGET_PACING == HB_LOCKSTEP || t >= next_tick) {
            hb_device_tick(&device, t);
            next_tick += TICK_US;
            if (next_tick < t) next_tick = t;
        }
    }
}
