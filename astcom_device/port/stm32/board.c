/* The example controller on an STM32F405 (QEMU's netduinoplus2): SysTick at the loop rate
 * runs the control tick; the main loop pumps USART1 (the framed link to the Relay). */
#include <stdint.h>
#include <string.h>

#include "ad_link.h"
#include "astcom_device.h"
#include "example_controller.h"
#include "mbedtls/memory_buffer_alloc.h"
#include "mbedtls/sha256.h"

#define REG(a) (*(volatile uint32_t *)(a))
#define USART1 0x40011000u
#define USART_SR REG(USART1 + 0x00)
#define USART_DR REG(USART1 + 0x04)
#define USART_BRR REG(USART1 + 0x08)
#define USART_CR1 REG(USART1 + 0x0c)
#define RCC_APB2ENR REG(0x40023844u)
#define SYST_CSR REG(0xe000e010u)
#define SYST_RVR REG(0xe000e014u)
#define SYST_CVR REG(0xe000e018u)
#define SCB_CPACR REG(0xe000ed88u)
#define CPU_HZ 168000000u
#define LOOP_HZ 10000u

/* ---- memory: everything the firmware uses is here, sized at compile time -------------- */
#ifndef FW_ARENA_BYTES
#define FW_ARENA_BYTES 40960u  /* ad_arena_bytes() of this configuration (firmware.mk) */
#endif
#ifndef FW_LINK_BYTES
#define FW_LINK_BYTES 8192u    /* ad_link_bytes(max_frame, max_reply, channels) */
#endif
#ifndef FW_MBEDTLS_BYTES
#define FW_MBEDTLS_BYTES 1024u /* mbedTLS's HMAC allocations */
#endif
static uint64_t arena[FW_ARENA_BYTES / 8];
static uint64_t link_mem[FW_LINK_BYTES / 8];
static unsigned char mbedtls_heap[FW_MBEDTLS_BYTES];
/* What this configuration needs, for a debugger or QEMU's monitor to read
 * (tests/device_c/test_device_qemu.py checks them against the sizes above). */
volatile uint32_t fw_arena_needed, fw_link_needed;
static ad_device *dev;
static ad_link *link;
static volatile uint64_t tick;
static volatile uint32_t ticks_in_isr;

/* ---- the host layer --------------------------------------------------------------------- */
static uint32_t primask_saved;
static volatile uint32_t lock_depth;
void ad_port_lock(void)
{
    uint32_t pm;
    __asm volatile("mrs %0, primask\n cpsid i" : "=r"(pm)::"memory");
    if (lock_depth++ == 0) primask_saved = pm;
}
void ad_port_unlock(void)
{
    if (--lock_depth == 0) __asm volatile("msr primask, %0" ::"r"(primask_saved) : "memory");
}

/* Nonces: SHA-256 of a pool stirred with the cycle counter at every received byte and
 * tick. QEMU's netduinoplus2 has no RNG; on a real STM32F4 read its RNG peripheral. */
static uint8_t pool[32];
static uint32_t stir_count;
static void stir(uint32_t x)
{
    for (int i = 0; i < 4; i++) pool[(stir_count + i) % 32] ^= (uint8_t)(x >> (8 * i));
    stir_count += 4;
}
int ad_port_random(uint8_t *out, size_t n)
{
    uint8_t block[32];
    static uint32_t counter;
    while (n) {
        uint32_t in[3] = {counter++, SYST_CVR, (uint32_t)tick};
        mbedtls_sha256_context c;
        mbedtls_sha256_init(&c);
        mbedtls_sha256_starts_ret(&c, 0);
        mbedtls_sha256_update_ret(&c, pool, sizeof pool);
        mbedtls_sha256_update_ret(&c, (const uint8_t *)in, sizeof in);
        mbedtls_sha256_finish_ret(&c, block);
        mbedtls_sha256_free(&c);
        memcpy(pool, block, sizeof pool);
        size_t k = n < 16 ? n : 16; /* hand out half of each block, keep the other half */
        memcpy(out, block + 16, k);
        out += k;
        n -= k;
    }
    return 0;
}

static int64_t start_us = 1735689600000000; /* 2025-01-01T00:00:00Z: no RTC in QEMU */
int64_t ad_port_wall_us(void) { return start_us + (int64_t)(tick * (1000000u / LOOP_HZ)); }

/* A failed assertion (libmpack checks its own invariants) stops here instead of printing
 * through newlib's fprintf: reset the core, as a watchdog would. */
void __assert_func(const char *file, int line, const char *fn, const char *expr)
{
    (void)file; (void)line; (void)fn; (void)expr;
    REG(0xe000ed0cu) = 0x05fa0004u; /* SCB AIRCR: VECTKEY | SYSRESETREQ */
    for (;;) {}
}

/* ---- the control tick --------------------------------------------------------------------- */
void systick_handler(void)
{
    uint64_t t = tick;
    int64_t t_us = ex_step(t);
    ad_tick(dev, t, t_us);
    tick = t + 1;
    ticks_in_isr++;
}

/* ---- USART1 ------------------------------------------------------------------------------- */
static void uart_init(void)
{
    RCC_APB2ENR |= 1u << 4;
    USART_BRR = CPU_HZ / 2u / 921600u;
    USART_CR1 = (1u << 13) | (1u << 3) | (1u << 2); /* UE, TE, RE */
}

static void uart_write_pending(void)
{
    uint8_t buf[64];
    size_t n;
    while ((n = ad_link_take(link, buf, sizeof buf)) > 0)
        for (size_t i = 0; i < n; i++) {
            while (!(USART_SR & (1u << 7))) {} /* TXE */
            USART_DR = buf[i];
        }
}

static void link_drain(void *io)
{
    (void)io;
    uart_write_pending();
}

int main(void)
{
    ad_config cfg;
    size_t nv, nf;
    char why[128];
    SCB_CPACR |= 0xfu << 20; /* the FPU */
    mbedtls_memory_buffer_alloc_init(mbedtls_heap, sizeof mbedtls_heap);
    ad_config_defaults(&cfg);
    cfg.name = "example-stm32";
    cfg.loop_rate_hz = LOOP_HZ;
    cfg.operator_password = FIRMWARE_PASSWORD;
    cfg.max_frame_bytes = 2048;
    cfg.max_reply_bytes = 1024; /* a bigger LIST goes out in parts */
    cfg.max_arg_bytes = 512;
    cfg.max_array_len = 1024;
    cfg.max_str_bytes = 256;
    cfg.max_depth = 8;
    cfg.max_messages = 16;
    cfg.max_names_per_message = 32;
    cfg.max_streams_per_client = 4;
    cfg.max_samplers = 4;
    cfg.max_clients = 2;
    cfg.max_pending = 1;
    cfg.max_pending_calls = 1;
    cfg.ring_ticks = LOOP_HZ / 50; /* 20 ms */
    /* password attempts: the rules of a host (§10) in a table of 2 addresses (the least
     * it may have: max_pending + 1); 80 bytes each */
    cfg.auth_max_addresses = 2;
    ex_init(cfg.loop_rate_hz, start_us, NULL);
    const ad_var *vars = ex_vars(EX_MAX_EXTRA, &nv);
    const ad_fn *fns = ex_fns(&nf);
    fw_arena_needed = (uint32_t)ad_arena_bytes(&cfg, vars, nv, fns, nf);
    fw_link_needed = (uint32_t)ad_link_bytes(cfg.max_frame_bytes, cfg.max_reply_bytes,
                                             cfg.max_clients + cfg.max_pending);
    dev = ad_init(arena, sizeof arena, &cfg, vars, nv, fns, nf, why, sizeof why);
    uart_init();
    if (dev) {
        link = ad_link_init(link_mem, sizeof link_mem, dev, cfg.max_frame_bytes,
                            cfg.max_reply_bytes, cfg.max_clients + cfg.max_pending, link_drain, NULL);
        if (!link)
            ad_snprintf(why, sizeof why, "the link needs %lu bytes; FW_LINK_BYTES is %lu",
                        (unsigned long)fw_link_needed, (unsigned long)sizeof link_mem);
    }
    if (!dev || !link) { /* say why on the UART, in plain text, and stop */
        for (const char *p = why; *p; p++) { while (!(USART_SR & (1u << 7))) {} USART_DR = (uint8_t)*p; }
        for (;;) {}
    }
    SYST_RVR = CPU_HZ / LOOP_HZ - 1;
    SYST_CVR = 0;
    SYST_CSR = 7; /* processor clock, interrupt, enable */
    ad_link_hello(link);
    uint8_t held[1];
    int have_held = 0;
    for (;;) {
        int64_t now = ad_port_wall_us();
        if (have_held && ad_link_can_feed(link)) have_held = ad_link_feed(link, held, 1, now) == 0;
        while (!have_held && (USART_SR & (1u << 5))) { /* RXNE */
            held[0] = (uint8_t)USART_DR;
            stir(SYST_CVR ^ ((uint32_t)held[0] << 24));
            have_held = ad_link_feed(link, held, 1, now) == 0;
        }
        ad_poll(dev, now);
        ad_link_service(link);
        uart_write_pending();
    }
}
