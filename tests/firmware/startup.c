/* Minimal bare-metal start for a Cortex-M under qemu: vector table, .data/.bss set-up, the
   FPU enabled when the build uses it, and ARM semihosting (BKPT 0xAB) for output and exit.
   No C library start-up code; no heap. */
#include <stdint.h>

#include "semihost.h"

extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss, _estack;
extern int main(void);
void reset_handler(void);
static void fault_handler(void);

__attribute__((section(".vectors"), used)) static void (*const vectors[16])(void) = {
    (void (*)(void))(&_estack), /* initial stack pointer */
    reset_handler,
    fault_handler, /* NMI */
    fault_handler, /* HardFault */
    fault_handler, fault_handler, fault_handler, 0, 0, 0, 0,
    fault_handler, fault_handler, 0, fault_handler, fault_handler,
};

static int semihost(int op, const void *arg)
{
    register int r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

void sh_write0(const char *text) { semihost(0x04, text); /* SYS_WRITE0 */ }

void sh_exit(int ok)
{
    /* SYS_EXIT with ADP_Stopped_ApplicationExit (qemu exits 0) or ADP_Stopped_RunTimeErrorUnknown */
    semihost(0x18, (const void *)(uintptr_t)(ok ? 0x20026 : 0x20023));
    for (;;) {
    }
}

static void fault_handler(void)
{
    sh_write0("fault\n");
    sh_exit(0);
}

void reset_handler(void)
{
    uint32_t *src = &_sidata, *dst;
#if defined(__ARM_FP)
    /* CPACR: full access to CP10 and CP11 (the FPU) */
    *(volatile uint32_t *)0xE000ED88u |= 0xFu << 20;
    __asm__ volatile("dsb\n\tisb" ::: "memory");
#endif
    for (dst = &_sdata; dst < &_edata;) *dst++ = *src++;
    for (dst = &_sbss; dst < &_ebss;) *dst++ = 0u;
    sh_exit(main() == 0);
}
