/* STM32 Nucleo-F446RE port of the firmware core (NOT RUN ON HARDWARE: it compiles in CI; bring-up steps
 * are in docs/firmware-nucleo-f446re.md).
 *
 * 168 MHz from HSI through the PLL. USART2 (ST-LINK VCP) carries protocol v1: RX interrupt into a ring,
 * TX by DMA1 stream 6 from a ring. TIM2 counts the quadrature encoder (32 bit, extended to 64 in software),
 * DAC1 drives the amplifier's analog set value, ADC1 reads its current monitor, PA8 enables it. TIM5 is a
 * free-running 1 MHz clock; the main loop ticks the core as fast as it runs, so each sample is taken when
 * the loop reaches it (jitter: one loop pass, a few microseconds). */
#include <stdint.h>

#include <math.h>

#include "board.h"
#include "hb_device.h"
#include "hb_hal.h"

#define REG(addr) (*(volatile uint32_t *)(addr))
#define RCC 0x40023800u
#define RCC_CR REG(RCC + 0x00)
#define RCC_PLLCFGR REG(RCC + 0x04)
#define RCC_CFGR REG(RCC + 0x08)
#define RCC_AHB1ENR REG(RCC + 0x30)
#define RCC_APB1ENR REG(RCC + 0x40)
#define RCC_APB2ENR REG(RCC + 0x44)
#define FLASH_ACR REG(0x40023C00u)
#define PWR_CR REG(0x40007000u)
#define GPIOA 0x40020000u
#define GPIOA_MODER REG(GPIOA + 0x00)
#define GPIOA_OSPEEDR REG(GPIOA + 0x08)
#define GPIOA_PUPDR REG(GPIOA + 0x0C)
#define GPIOA_BSRR REG(GPIOA + 0x18)
#define GPIOA_AFRL REG(GPIOA + 0x20)
#define USART2 0x40004400u
#define USART2_SR REG(USART2 + 0x00)
#define USART2_DR REG(USART2 + 0x04)
#define USART2_BRR REG(USART2 + 0x08)
#define USART2_CR1 REG(USART2 + 0x0C)
#define USART2_CR3 REG(USART2 + 0x14)
#define TIM2 0x40000000u
#define TIM2_CR1 REG(TIM2 + 0x00)
#define TIM2_SMCR REG(TIM2 + 0x08)
#define TIM2_CCMR1 REG(TIM2 + 0x18)
#define TIM2_CCER REG(TIM2 + 0x20)
#define TIM2_CNT REG(TIM2 + 0x24)
#define TIM2_ARR REG(TIM2 + 0x2C)
#define TIM5 0x40000C00u
#define TIM5_CR1 REG(TIM5 + 0x00)
#define TIM5_EGR REG(TIM5 + 0x14)
#define TIM5_CNT REG(TIM5 + 0x24)
#define TIM5_PSC REG(TIM5 + 0x28)
#define TIM5_ARR REG(TIM5 + 0x2C)
#define DAC_CR REG(0x40007400u)
#define DAC_DHR12R1 REG(0x40007408u)
#define ADC1 0x40012000u
#define ADC1_SR REG(ADC1 + 0x00)
#define ADC1_CR2 REG(ADC1 + 0x08)
#define ADC1_SMPR2 REG(ADC1 + 0x10)
#define ADC1_SQR3 REG(ADC1 + 0x34)
#define ADC1_DR REG(ADC1 + 0x4C)
#define ADC_CCR REG(0x40012304u)
#define DMA1 0x40026000u
#define DMA1_HIFCR REG(DMA1 + 0x0C)
#define DMA1_S6CR REG(DMA1 + 0xA0)
#define DMA1_S6NDTR REG(DMA1 + 0xA4)
#define DMA1_S6PAR REG(DMA1 + 0xA8)
#define DMA1_S6M0AR REG(DMA1 + 0xAC)
#define NVIC_ISER1 REG(0xE000E104u)

#define APB1_HZ 42000000u
#define RX_RING 4096u                 /* bytes, powers of two */
#define TX_RING 16384u

typedef struct {
    int64_t counts;                   /* encoder count extended to 64 bits */
    uint32_t last_cnt;
    uint32_t tx_dropped;
} board_hal;

static board_hal hal;
static hb_device device;
static volatile uint8_t rx_ring[RX_RING];
static volatile uint32_t rx_head, rx_tail;
static uint8_t tx_ring[TX_RING];
static uint32_t tx_head, tx_tail, tx_busy;  /* tx_busy: bytes the running DMA transfer takes */
static uint32_t clock_high, clock_last;

static void clock_init(void) {
    RCC_APB1ENR |= 1u << 28;                       /* PWR */
    PWR_CR |= 3u << 14;                            /* voltage scale 1 */
    FLASH_ACR = (1u << 8) | (1u << 9) | (1u << 10) | 5u;  /* prefetch, I/D caches, 5 wait states */
    /* HSI 16 MHz / M 8 * N 168 / P 2 = 168 MHz; Q 7 */
    RCC_PLLCFGR = 8u | (168u << 6) | (0u << 16) | (0u << 22) | (7u << 24);
    RCC_CR |= 1u << 24;
    while (!(RCC_CR & (1u << 25))) {
    }
    RCC_CFGR = (5u << 10) | (4u << 13);            /* APB1 /4 = 42 MHz, APB2 /2 = 84 MHz */
    RCC_CFGR |= 2u;                                /* SYSCLK = PLL */
    while ((RCC_CFGR & (3u << 2)) != (2u << 2)) {
    }
}

static void gpio_af(uint32_t pin, uint32_t af) {
    GPIOA_MODER = (GPIOA_MODER & ~(3u << (2 * pin))) | (2u << (2 * pin));
    GPIOA_OSPEEDR |= 3u << (2 * pin);
    GPIOA_AFRL = (GPIOA_AFRL & ~(0xFu << (4 * pin))) | (af << (4 * pin));
}

static void peripherals_init(void) {
    RCC_AHB1ENR |= 1u | (1u << 21);                /* GPIOA, DMA1 */
    RCC_APB1ENR |= 1u | (1u << 3) | (1u << 17) | (1u << 29);  /* TIM2, TIM5, USART2, DAC */
    RCC_APB2ENR |= 1u << 8;                        /* ADC1 */
    /* encoder: PA0, PA1 = TIM2 CH1/CH2 (AF1), pull-ups for open-collector encoders */
    gpio_af(0, 1);
    gpio_af(1, 1);
    GPIOA_PUPDR |= (1u << 0) | (1u << 2);
    TIM2_ARR = 0xFFFFFFFFu;
    TIM2_CCMR1 = 1u | (1u << 8) | (3u << 4) | (3u << 12);  /* TI1, TI2 inputs, filter N=8 */
    TIM2_CCER = 0;
    TIM2_SMCR = 3u;                                /* encoder mode 3: count on both edges of both */
    TIM2_CR1 = 1u;
    /* USART2: PA2 TX, PA3 RX (AF7) */
    gpio_af(2, 7);
    gpio_af(3, 7);
    USART2_BRR = APB1_HZ / BOARD_BAUD;
    USART2_CR3 = 1u << 7;                          /* DMA for TX */
    USART2_CR1 = (1u << 13) | (1u << 5) | (1u << 3) | (1u << 2);  /* UE, RXNEIE, TE, RE */
    NVIC_ISER1 = 1u << (38 - 32);
    DMA1_S6PAR = USART2 + 0x04;
    /* DAC1 OUT1 on PA4 (analog), mid-scale = 0 A */
    GPIOA_MODER |= 3u << (2 * 4);
    DAC_DHR12R1 = 2048u;
    DAC_CR = 1u;
    /* ADC1 IN6 on PA6 (analog), 84 cycles sampling, PCLK2/4 */
    GPIOA_MODER |= 3u << (2 * 6);
    ADC_CCR = 1u << 16;
    ADC1_SMPR2 = 4u << (3 * 6);
    ADC1_SQR3 = 6u;
    ADC1_CR2 = 1u;
    /* amplifier enable: PA8 output, low (off) */
    GPIOA_MODER = (GPIOA_MODER & ~(3u << 16)) | (1u << 16);
    GPIOA_BSRR = 1u << (8 + 16);
    /* TIM5: free-running 1 MHz (timer clock 2 x APB1 = 84 MHz) */
    TIM5_PSC = 84u - 1u;
    TIM5_ARR = 0xFFFFFFFFu;
    TIM5_EGR = 1u;
    TIM5_CR1 = 1u;
}

static uint64_t now_us(void) {
    uint32_t cnt = TIM5_CNT;
    if (cnt < clock_last) clock_high++;
    clock_last = cnt;
    return (uint64_t)clock_high << 32 | cnt;
}

void USART2_IRQHandler(void) {
    uint32_t sr = USART2_SR;
    if (sr & ((1u << 5) | (1u << 3))) {            /* RXNE or overrun: reading DR clears both */
        uint8_t b = (uint8_t)USART2_DR;
        if (rx_head - rx_tail < RX_RING) rx_ring[rx_head++ % RX_RING] = b;
    }
}

static void tx_kick(void) {
    if (tx_busy) {
        if (DMA1_S6CR & 1u) return;                /* still running */
        tx_tail += tx_busy;
        tx_busy = 0;
    }
    uint32_t pending = tx_head - tx_tail;
    if (!pending) return;
    uint32_t start = tx_tail % TX_RING, run = TX_RING - start;
    tx_busy = pending < run ? pending : run;
    DMA1_HIFCR = 0x3Du << 16;                      /* clear stream 6 flags */
    DMA1_S6M0AR = (uint32_t)(uintptr_t)&tx_ring[start];
    DMA1_S6NDTR = tx_busy;
    DMA1_S6CR = (4u << 25) | (1u << 10) | (1u << 6) | 1u;  /* channel 4, memory increment, mem->periph, EN */
}

void hb_hal_serial_write(void *h, const uint8_t *data, size_t n) {
    board_hal *b = h;
    tx_kick();
    if (tx_head - tx_tail + n > TX_RING) {
        b->tx_dropped++;                           /* the host reads too slowly: the frame is lost */
        return;
    }
    for (size_t i = 0; i < n; i++) tx_ring[tx_head++ % TX_RING] = data[i];
    tx_kick();
}

/* CAN (bxCAN on PA11/PA12) is not wired in this port; the device is set up for its serial link. */
void hb_hal_can_write(void *h, uint16_t id, const uint8_t *data, uint8_t len) {
    (void)h;
    (void)id;
    (void)data;
    (void)len;
}

int hb_hal_configure(void *h, const hb_config *config) {
    board_hal *b = h;
    (void)config;
    TIM2_CNT = 0;                                  /* CONFIG zeroes the encoder count */
    b->counts = 0;
    b->last_cnt = 0;
    return 0;
}

void hb_hal_measure(void *h, int64_t *counts, hb_real *current) {
    board_hal *b = h;
    ADC1_CR2 |= 1u << 30;                          /* start the conversion, read the encoder meanwhile */
    uint32_t cnt = TIM2_CNT;
    b->counts += (int32_t)(cnt - b->last_cnt);     /* exact while |delta| < 2^31 counts per sample */
    b->last_cnt = cnt;
    while (!(ADC1_SR & 2u)) {
    }
    int32_t code = (int32_t)(ADC1_DR & 0xFFFu) - 2048;
    *counts = b->counts;
    *current = (hb_real)code * (hb_real)(BOARD_ADC_AMPS_FULL_SCALE / 2048.0f);
}

void hb_hal_apply(void *h, hb_real current, int enabled) {
    (void)h;
    hb_real code = enabled ? (hb_real)2048 + current * (hb_real)(2048.0f / BOARD_DAC_AMPS_FULL_SCALE) : 2048;
    if (code < 0) code = 0;
    if (code > 4095) code = 4095;
    DAC_DHR12R1 = (uint32_t)(code + (hb_real)0.5);
    GPIOA_BSRR = enabled ? 1u << 8 : 1u << (8 + 16);
}

hb_real hb_hal_temperature(void *h) {
    (void)h;
    return (hb_real)NAN;                           /* no winding sensor on this board (setup.sensors = 0) */
}

int main(void) {
    clock_init();
    peripherals_init();
    hb_device_setup setup = {BOARD_MODEL, BOARD_SERIAL, "hilbench c-core " HB_CORE_VERSION " nucleo-f446re",
                             HB_BUFFER_CAPACITY, HB_MAX_BLOCK, HB_REALTIME, HB_LINK_SERIAL, 1,
                             BOARD_VELOCITY_KP, BOARD_VELOCITY_KI, 0};  /* no temperature sensor */
    hb_device_init(&device, &setup, &hal);
    uint8_t rx[128];
    for (;;) {
        size_t n = 0;
        while (n < sizeof rx && rx_tail != rx_head) rx[n++] = rx_ring[rx_tail++ % RX_RING];
        if (n) hb_device_rx_bytes(&device, rx, n, now_us());
        hb_device_tick(&device, now_us());
        hb_device_count_dropped(&device, hal.tx_dropped);
        hal.tx_dropped = 0;
        tx_kick();
    }
}
