/* STM32F446RE vector table up to USART2 (IRQ 38); reset code: ../cortex_m_reset.c. */
extern char _estack;
void Reset_Handler(void);
void Default_Handler(void);
void USART2_IRQHandler(void);

#define N_VECTORS (16 + 39)

__attribute__((section(".vectors"), used)) static const void *const vectors[N_VECTORS] = {
    [0] = &_estack,
    [1] = (void *)Reset_Handler,
    [2 ... 15] = (void *)Default_Handler,
    [16 ... 16 + 37] = (void *)Default_Handler,
    [16 + 38] = (void *)USART2_IRQHandler,
};
