/* mbedTLS for the firmware: HMAC-SHA256 only, its few allocations from a fixed buffer
 * (memory_buffer_alloc), no file system, no entropy module (the nonces come from the
 * board's ad_port_random). */
#ifndef MBEDTLS_CONFIG_M4_H
#define MBEDTLS_CONFIG_M4_H
#define MBEDTLS_MD_C
#define MBEDTLS_SHA256_C
#define MBEDTLS_SHA256_SMALLER
#define MBEDTLS_PLATFORM_C
#define MBEDTLS_PLATFORM_MEMORY
#define MBEDTLS_MEMORY_BUFFER_ALLOC_C
#define MBEDTLS_PLATFORM_NO_STD_FUNCTIONS
#define MBEDTLS_PLATFORM_SNPRINTF_MACRO snprintf
#define MBEDTLS_PLATFORM_PRINTF_MACRO(...) 0
#define MBEDTLS_PLATFORM_FPRINTF_MACRO(...) 0
#define MBEDTLS_PLATFORM_EXIT_MACRO(x) for (;;) {}
#include "mbedtls/check_config.h"
#endif
