/* Vector table and reset for the STM32F405 (Cortex-M4F). */
#include <stdint.h>
#include <string.h>

extern uint32_t _data_load, _data_start, _data_end, _bss_start, _bss_end, _stack_top;
int main(void);
void systick_handler(void);
void reset_handler(void);

static void default_handler(void) { for (;;) {} }

__attribute__((section(".vectors"), used)) static void (*const vectors[16 + 82])(void) = {
    (void (*)(void))(&_stack_top), reset_handler, default_handler, default_handler,
    default_handler, default_handler, default_handler, 0, 0, 0, 0, default_handler,
    default_handler, 0, default_handler, systick_handler,
};

/* The stack is painted with 0xa5 at reset: how deep it ever got can be read later (a
 * debugger, QEMU's monitor) as the first byte from its bottom that is not 0xa5. */
extern uint32_t _stack_bottom;
#define STACK_PAINT 0xa5a5a5a5u

void reset_handler(void)
{
    memcpy(&_data_start, &_data_load, (size_t)((char *)&_data_end - (char *)&_data_start));
    memset(&_bss_start, 0, (size_t)((char *)&_bss_end - (char *)&_bss_start));
    uint32_t *sp;
    __asm volatile("mov %0, sp" : "=r"(sp));
    for (uint32_t *p = &_stack_bottom; p < sp - 16; p++) *p = STACK_PAINT;
    main();
    for (;;) {}
}
