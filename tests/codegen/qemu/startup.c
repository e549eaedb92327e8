/* Reset for a Cortex-M4F on QEMU's mps2-an386: enable the FPU, then newlib's _start (rdimon
 * semihosting: main's argv, stdio and files on the host). etobs' conformance check only. */
#include <stdint.h>

extern void _start(void);
extern uint32_t __stack_top;

void reset_handler(void) {
    volatile uint32_t *cpacr = (uint32_t *)0xE000ED88u;
    *cpacr |= 0xFu << 20; /* CP10, CP11: full access (the FPU) */
    __asm volatile("dsb\n\tisb");
    _start();
    for (;;) {
    }
}

static void fault(void) {
    for (;;) {
    }
}

__attribute__((section(".vectors"), used)) const uintptr_t vectors[16] = {
    (uintptr_t)&__stack_top, (uintptr_t)reset_handler, (uintptr_t)fault, (uintptr_t)fault,
    (uintptr_t)fault, (uintptr_t)fault, (uintptr_t)fault, 0, 0, 0, 0, (uintptr_t)fault, (uintptr_t)fault, 0,
    (uintptr_t)fault, (uintptr_t)fault,
};
