/* mps2-an386 vector table (reset code: ../cortex_m_reset.c). */
extern char _estack;
void Reset_Handler(void);
void Default_Handler(void);
void UART0_RX_Handler(void);

__attribute__((section(".vectors"), used)) static const void *const vectors[17] = {
    &_estack, (void *)Reset_Handler, (void *)Default_Handler, (void *)Default_Handler, /* NMI, HardFault */
    (void *)Default_Handler, (void *)Default_Handler, (void *)Default_Handler,        /* MemManage, Bus, Usage */
    0, 0, 0, 0, (void *)Default_Handler, (void *)Default_Handler, 0,                   /* SVC, DebugMon */
    (void *)Default_Handler, (void *)Default_Handler,                                  /* PendSV, SysTick */
    (void *)UART0_RX_Handler,                                                          /* IRQ 0: UART0 RX */
};
