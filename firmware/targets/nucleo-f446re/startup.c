/* STM32F446RE start-up: vector table (up to USART2, IRQ 38), .data/.bss, FPU on, then main(). */
#include <stdint.h>

extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss, _estack;
int main(void);
void Reset_Handler(void);
void USART2_IRQHandler(void);

#define SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)
#define N_VECTORS (16 + 39)

static void Default_Handler(void) {
    for (;;) {
    }
}

__attribute__((section(".vectors"), used)) static const void *const vectors[N_VECTORS] = {
    [0] = &_estack,
    [1] = (void *)Reset_Handler,
    [2 ... 15] = (void *)Default_Handler,
    [16 ... 16 + 37] = (void *)Default_Handler,
    [16 + 38] = (void *)USART2_IRQHandler,
};

void Reset_Handler(void) {
    uint32_t *src = &_sidata, *dst = &_sdata;
    while (dst < &_edata) *dst++ = *src++;
    for (dst = &_sbss; dst < &_ebss;) *dst++ = 0;
    SCB_CPACR |= 0xFu << 20;  /* CP10 and CP11: full access to the FPU */
    __asm volatile("dsb\n\tisb" ::: "memory");
    main();
    for (;;) {
    }
}
