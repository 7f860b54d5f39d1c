/* Cortex-M4F start-up: vector table, .data/.bss initialisation, FPU on, then main(). */
#include <stdint.h>

extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss, _estack;
int main(void);
void Reset_Handler(void);
void SysTick_Handler(void);
void UART0_RX_Handler(void);

#define SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)

static void Default_Handler(void) {
    for (;;) {
    }
}

__attribute__((section(".vectors"), used)) static const void *const vectors[17] = {
    &_estack, (void *)Reset_Handler, (void *)Default_Handler, (void *)Default_Handler, /* NMI, HardFault */
    (void *)Default_Handler, (void *)Default_Handler, (void *)Default_Handler,        /* MemManage, Bus, Usage */
    0, 0, 0, 0, (void *)Default_Handler, (void *)Default_Handler, 0,                   /* SVC, DebugMon */
    (void *)Default_Handler, (void *)SysTick_Handler,                                  /* PendSV, SysTick */
    (void *)UART0_RX_Handler,                                                          /* IRQ 0: UART0 RX */
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
